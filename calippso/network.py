"""The contact network of a packing, its certificate, and the stage that finishes a run.

`ContactNetwork` is a value: the contacts between stable particles, their forces, the
rattlers. The functions here take a configuration (a `NeighborSearch`, lengths in mean
diameters) and a network and return new values, never changing their arguments; when they
repair something they also return the note that says so, for the run's status.

- `certify_network`: the jamming point of an isostatic network by Newton's method
  (`calippso.certification.newton`), accepted only with its certificate (positive forces, no other overlap).
- `touching_network`: at a degenerate jamming point, the touching pairs as the network when
  the LP duals missed contacts.
- `polished_forces`: forces refined by least squares on the equilibrium equations.
- `remove_roundoff_overlaps`: all diameters shrunk by the round-off overlap left at the end.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace

import numpy as np

from .geometry.boundaries import Boundaries
from .geometry.contacts import force_balance, isostaticity_gap, polish_forces, positive_self_stress
from .geometry.neighbors import NEAR_CONTACT_SLACK, NeighborSearch, Pairs, shrink_to_margin
from .certification.newton import NEWTON_FAILED, Refinement, refine_isostatic
from .geometry.rattlers import remove_rattlers, separate_rattlers
from .geometry.walls import (WallRows, empty_walls, wall_equilibrium_columns, wall_ids,
                             wall_rows_of, wall_rows_within)

__all__ = ["ContactNetwork", "Certified", "RoundoffShrink", "network_key", "network_balance",
           "overlaps_outside", "certify_network", "touching_network", "polished_forces",
           "remove_roundoff_overlaps", "walls_near_contact", "NEWTON_OVERLAP_TOLERANCE",
           "GEOMETRIC_CONTACT_GAP",
           "ROUNDOFF_SHRINK_MARGIN"]

#: A pair outside the contact network may overlap by at most this relative gap at a Newton
#: solution (round-off); more means the network is not the jammed one.
NEWTON_OVERLAP_TOLERANCE = 1e-12
#: Pairs closer than this relative gap count as touching (`touching_network`, and the pairs a
#: guessed network must not leave out, `certify_network`).
GEOMETRIC_CONTACT_GAP = 1e-11
#: `remove_roundoff_overlaps` leaves the closest pair this relative gap (four units of
#: round-off).
ROUNDOFF_SHRINK_MARGIN = 4 * np.finfo(float).eps


@dataclass(frozen=True, eq=False)
class ContactNetwork:
    """Contacts between stable particles and their forces.

    Attributes
    ----------
    i, j : ndarray, shape (M,), int64
        The contacts' particles (i < j).
    forces : ndarray, shape (M,)
        Force magnitudes f = μ/2 in the LP's normalisation (not normalised to mean 1).
    rattlers : ndarray, shape (N,), bool
        Particles outside the network.
    normalization : float
        Σ λ σ² over the contacts (1 up to round-off for LP duals; NaN for a guessed network
        before its forces are known).
    solver : str
        The backend whose duals gave the network ("none" for one that no LP gave).
    from_lp : bool
        The network and forces are an LP's duals (a force clean-up LP can then repair them).
    wall_particle, wall : ndarray, shape (K,), int64
        The contacts with flat walls: particle and wall (`calippso.geometry.walls`); empty in a
        periodic box.
    wall_forces : ndarray, shape (K,)
        Their force magnitudes, in the units of `forces`.
    """

    i: np.ndarray
    j: np.ndarray
    forces: np.ndarray
    rattlers: np.ndarray
    normalization: float
    solver: str
    from_lp: bool
    wall_particle: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    wall: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    wall_forces: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def n_contacts(self) -> int:
        """Number of contacts N_c: between particles (M) and with walls (K)."""
        return int(self.i.shape[0] + self.wall_particle.shape[0])

    @property
    def walls(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """(particle, wall, forces) of the wall contacts, or None without any."""
        if not self.wall_particle.shape[0]:
            return None
        return self.wall_particle, self.wall, self.wall_forces

    @property
    def n_stable(self) -> int:
        """Number of stable (non-rattler) particles."""
        return int(self.rattlers.size - self.rattlers.sum())

    def key(self) -> str:
        """A digest of the contacts, wall contacts included (`network_key`)."""
        return network_key(self.i, self.j, self.rattlers.size, self.wall_particle, self.wall)


def network_key(i: np.ndarray, j: np.ndarray, n: int,
                wall_particle: np.ndarray | None = None, wall: np.ndarray | None = None) -> str:
    """A digest of a contact network: its sorted pair keys i N + j (N particles), and, in a
    container, its wall contacts (particle, wall) sorted."""
    digest = hashlib.sha256(np.sort(i * n + j).tobytes())
    if wall_particle is not None and wall_particle.size:
        order = np.lexsort((wall, wall_particle))
        digest.update(np.column_stack([wall_particle[order], wall[order]]).astype(
            np.int64).tobytes())
    return digest.hexdigest()


def network_balance(search: NeighborSearch, network: ContactNetwork,
                    boundaries: Boundaries | None = None) -> float:
    """max over stable particles of |Σ_j f_ij n_ij + Σ_w f_w e_w| / mean force, at the
    geometry of `search` in the container `boundaries` (None: periodic)."""
    current = search.pairs_of(network.i, network.j)
    return force_balance(network.rattlers.size, current.i, current.j,
                         current.vectors / current.distances[:, None], network.forces,
                         ~network.rattlers, _wall_part(search, network, boundaries))


def _wall_part(search: NeighborSearch, network: ContactNetwork,
               boundaries: Boundaries | None) -> tuple | None:
    """(particle, inward normals, forces) of the network's wall contacts at the geometry of
    `search` (`calippso.geometry.contacts.force_balance`), or None without any."""
    if network.walls is None:
        return None
    walls = _wall_geometry(search, network, boundaries)
    return walls.particle, walls.normals, network.wall_forces


def _wall_geometry(search: NeighborSearch, network: ContactNetwork,
                   boundaries: Boundaries | None) -> WallRows:
    """The geometry of the network's wall contacts in the configuration of `search`."""
    return wall_rows_of(search.positions, search.diameters, search.box, network.wall_particle,
                        network.wall, () if boundaries is None else boundaries.cylinder_axes)


def overlaps_outside(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                     contact_keys: np.ndarray, periodic: np.ndarray | None = None
                     ) -> tuple[NeighborSearch, Pairs, np.ndarray]:
    """The neighbour search of a configuration, its pairs near contact, and which of those
    overlap beyond `NEWTON_OVERLAP_TOLERANCE` without being a contact.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    contact_keys : ndarray, shape (M,), int64
        Sorted keys i N + j of the contacts.
    periodic : ndarray, shape (d,), bool, optional
        The periodic axes; None: all of them.

    Returns
    -------
    search : NeighborSearch
    close : Pairs
        `NeighborSearch.pairs_near_contact`.
    overlapping : ndarray, shape (len(close),), bool
    """
    search = NeighborSearch(positions, diameters, box, periodic)
    close = search.pairs_near_contact()
    is_contact = np.isin(close.i * positions.shape[0] + close.j, contact_keys)
    return search, close, ~is_contact & (close.gaps < -NEWTON_OVERLAP_TOLERANCE)


@dataclass(frozen=True, eq=False)
class Certified:
    """A certified jamming point (`certify_network`).

    Attributes
    ----------
    positions : ndarray, shape (N, d)
        The jamming point's centres (mean diameters).
    diameters : ndarray, shape (N,)
    search : NeighborSearch
        The neighbour search of that configuration.
    network : ContactNetwork
        The network with the certificate's self-stress as forces (``from_lp=False``).
    balance : float
        Its force balance (`network_balance`).
    min_gap : float
        Smallest relative gap of the configuration (+inf if no pair is near contact).
    refinement : Refinement
        Newton's own account (iterations, factorisations, residual, growth, move).
    """

    positions: np.ndarray
    diameters: np.ndarray
    search: NeighborSearch
    network: ContactNetwork
    balance: float
    min_gap: float
    refinement: Refinement


def certify_network(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                    network: ContactNetwork, *, guessed: bool = False,
                    refined: Refinement | None = None,
                    boundaries: Boundaries | None = None) -> tuple[Certified | None, str]:
    """Solve the contact equations of an isostatic network and certify the solution.

    Certified means: every force positive (wall contacts included) and no other pair
    overlapping, nor any other particle crossing a wall, beyond `NEWTON_OVERLAP_TOLERANCE`
    (see `calippso.certification.newton`). In a periodic box, rattlers that the moved cages now overlap are
    first moved out of the way (`calippso.geometry.rattlers.separate_rattlers`). A `guessed` network
    (not an LP's) must also be the whole contact network: another touching pair of stable
    particles, or a stable particle touching a wall outside the network (h <
    `GEOMETRIC_CONTACT_GAP`), means a degenerate (hyperstatic) packing, left to the LPs.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Current centres (mean diameters).
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    network : ContactNetwork
        Its forces are not used; its wall contacts are part of the network.
    guessed : bool
        The network was guessed from the input, not read from an LP's duals.
    refined : Refinement, optional
        Newton's solution from `positions`, when already computed (`calippso.certification.network_first`).
    boundaries : Boundaries, optional
        The box's boundaries (`calippso.geometry.boundaries`); None: periodic along every axis.

    Returns
    -------
    (Certified or None, str)
        The certified point and "", or None and why it failed.
    """
    n = positions.shape[0]
    periodic = None if boundaries is None or boundaries.is_periodic else boundaries.periodic
    if refined is None:
        refined = refine_isostatic(positions, diameters, box, network.i, network.j,
                                   ~network.rattlers, wall_particle=network.wall_particle,
                                   wall=network.wall, boundaries=boundaries)
    if refined is None:
        return None, NEWTON_FAILED
    order = np.sort(network.i * n + network.j)
    moved = refined.positions
    search, close, overlapping = overlaps_outside(moved, refined.diameters, box, order,
                                                  periodic)
    near_walls = walls_near_contact(search, boundaries)
    crossing = _crossing(near_walls, network)
    if refined.positive and (overlapping.any() or crossing.any()) and np.all(
            network.rattlers[close.i[overlapping]] | network.rattlers[close.j[overlapping]]) \
            and np.all(network.rattlers[near_walls.particle[crossing]]):
        # only rattlers overlap: the cage moved under a rattler that touched it
        separated = separate_rattlers(moved, refined.diameters, box, network.rattlers,
                                      boundaries=boundaries)
        if separated is not None:
            moved = separated
            search, close, overlapping = overlaps_outside(moved, refined.diameters, box, order,
                                                          periodic)
            near_walls = walls_near_contact(search, boundaries)
    outside_walls = _outside_network(near_walls, network)
    crossing = int(np.count_nonzero(_crossing(near_walls, network)))
    touching = 0
    if guessed:
        stable = ~network.rattlers
        outside = ~np.isin(close.i * n + close.j, order)
        touching = int(np.count_nonzero(outside & (close.gaps < GEOMETRIC_CONTACT_GAP)
                                        & stable[close.i] & stable[close.j]))
        touching += int(np.count_nonzero(outside_walls & (near_walls.gaps < GEOMETRIC_CONTACT_GAP)
                                         & stable[near_walls.particle]))
    if not refined.positive:
        return None, "a non-positive force"
    if overlapping.any():
        return None, f"{int(overlapping.sum())} other pair(s) would overlap"
    if crossing:
        return None, f"{crossing} other particle(s) would cross a wall"
    if touching:
        return None, f"{touching} other pair(s) touch (a hyperstatic packing)"
    current = search.pairs_of(network.i, network.j)
    walls = _wall_geometry(search, network, boundaries)
    normalization = float(refined.forces @ (current.sigma**2 / current.distances)
                          + refined.wall_forces @ (walls.sigma**2 / walls.distances))
    certified = replace(network, forces=refined.forces, wall_forces=refined.wall_forces,
                        normalization=normalization, from_lp=False)
    return Certified(moved, refined.diameters, search, certified,
                     network_balance(search, certified, boundaries), close.smallest_gap(),
                     refined), ""
def _outside_network(walls: WallRows, network: ContactNetwork) -> np.ndarray:
    """Which particle–wall pairs are not wall contacts of the network, shape (K,), bool."""
    n_walls = wall_ids(walls.normals.shape[1])
    return ~np.isin(walls.keys(n_walls), network.wall_particle * n_walls + network.wall)


def _crossing(walls: WallRows, network: ContactNetwork) -> np.ndarray:
    """Which particle–wall pairs outside the network cross their wall beyond
    `NEWTON_OVERLAP_TOLERANCE`, shape (K,), bool."""
    return _outside_network(walls, network) & (walls.gaps < -NEWTON_OVERLAP_TOLERANCE)


def touching_network(search: NeighborSearch, network: ContactNetwork, balance: float, d: int,
                     balance_tolerance: float, boundaries: Boundaries | None = None
                     ) -> tuple[ContactNetwork, float, str | None]:
    """The touching pairs as the contact network, when the LP's duals missed contacts.

    At a degenerate jammed point (crystals, other hyperstatic packings) the LP has many
    optimal dual solutions, and a vertex solution may put its weight on a few rows only,
    leaving the others, and particles, looking like non-contacts and rattlers. When the LP
    network is hypostatic or has no stable particle, and the pairs that touch
    (h < `GEOMETRIC_CONTACT_GAP`) give a network with more stable particles (or as many,
    and more contacts), the touching network is used instead, with the positive
    self-stress near uniform forces that `positive_self_stress` finds, if there is one and
    it balances to `balance_tolerance`. Otherwise the LP network is kept. In a container
    (`boundaries`, default periodic), the particles touching a wall count too
    (`calippso.geometry.walls`), and its zero modes enter the isostatic count.

    Returns
    -------
    (ContactNetwork, float, str or None)
        The network, its force balance, and the note when the touching network was taken.
    """
    n = network.rattlers.size
    zero_modes = None if boundaries is None else boundaries.zero_modes
    if network.n_stable > 0 and isostaticity_gap(network.n_contacts, network.n_stable, d,
                                                 zero_modes) >= 0:
        return network, balance, None
    close = search.pairs_near_contact()
    touching = close.subset(close.gaps < GEOMETRIC_CONTACT_GAP)
    walls = walls_near_contact(search, boundaries)
    walls = walls.subset(walls.gaps < GEOMETRIC_CONTACT_GAP)
    rattlers, kept = remove_rattlers(n, d, touching.i, touching.j,
                                     walls.particle if len(walls) else None)
    touching = touching.subset(kept)
    walls = walls.subset(~rattlers[walls.particle])
    n_stable_touching = int(np.count_nonzero(~rattlers))
    if (n_stable_touching, len(touching) + len(walls)) <= (network.n_stable,
                                                            network.n_contacts):
        return network, balance, None
    normals = touching.vectors / touching.distances[:, None]
    weights = touching.sigma**2 / touching.distances
    extra = None
    if len(walls):
        extra = wall_equilibrium_columns(n, walls.particle, walls.normals)
        weights = np.concatenate([weights, walls.sigma**2 / walls.distances])
    forces = positive_self_stress(n, touching.i, touching.j, normals, weights, extra)
    if forces is None:
        return network, balance, None
    m = len(touching)
    wall_part = (walls.particle, walls.normals, forces[m:]) if len(walls) else None
    new_balance = force_balance(n, touching.i, touching.j, normals, forces[:m], ~rattlers,
                                wall_part)
    if new_balance > balance_tolerance:
        return network, balance, None
    note = (f"contacts taken from the touching pairs (h < {GEOMETRIC_CONTACT_GAP:g}): the LP "
            f"duals are degenerate here; forces are a positive self-stress near uniform")
    return (ContactNetwork(touching.i, touching.j, forces[:m], rattlers,
                           float(forces @ weights), network.solver, from_lp=False,
                           wall_particle=walls.particle, wall=walls.wall,
                           wall_forces=forces[m:]), new_balance, note)


def polished_forces(search: NeighborSearch, network: ContactNetwork, balance: float,
                    boundaries: Boundaries | None = None
                    ) -> tuple[ContactNetwork, float, str | None]:
    """Forces refined by least squares on the equilibrium equations, if that helps.

    Wall contacts (`ContactNetwork.walls`) are polished with the pair contacts, as further
    columns of the equilibrium matrix (`calippso.geometry.walls.wall_equilibrium_columns`).

    Returns
    -------
    (ContactNetwork, float, str or None)
        The network with the polished forces, their balance, and the note, when they are kept
        (all positive and better balanced); otherwise `network` itself and `balance`.
    """
    n = network.rattlers.size
    geometry = search.pairs_of(network.i, network.j)
    normals = geometry.vectors / geometry.distances[:, None]
    weights = geometry.sigma**2 / geometry.distances
    forces, extra = network.forces, None
    if network.walls is not None:
        walls = _wall_geometry(search, network, boundaries)
        extra = wall_equilibrium_columns(n, walls.particle, walls.normals)
        weights = np.concatenate([weights, walls.sigma**2 / walls.distances])
        forces = np.concatenate([forces, network.wall_forces])
    polished = polish_forces(n, geometry.i, geometry.j, normals, weights, forces, extra)
    m = network.i.shape[0]
    new = replace(network, forces=polished[:m], wall_forces=polished[m:])
    new_balance = force_balance(n, geometry.i, geometry.j, normals, new.forces,
                                ~network.rattlers, _wall_part(search, new, boundaries))
    if np.all(polished > 0) and new_balance < balance:
        return (new, new_balance,
                f"forces polished by least squares (balance {balance:.1e} -> {new_balance:.1e})")
    return network, balance, None


@dataclass(frozen=True, eq=False)
class RoundoffShrink:
    """All diameters shrunk to remove the round-off overlaps of a final configuration.

    Attributes
    ----------
    factor : float
        The factor on every diameter (< 1).
    search : NeighborSearch
        The configuration with the shrunk diameters.
    min_gap : float
        Its smallest relative gap (+inf if no pair is near contact).
    note : str
    """

    factor: float
    search: NeighborSearch
    min_gap: float
    note: str


def remove_roundoff_overlaps(search: NeighborSearch,
                             boundaries: Boundaries | None = None) -> RoundoffShrink | None:
    """The shrink that leaves no overlap (`calippso.geometry.neighbors.shrink_to_margin`, closest
    pair `ROUNDOFF_SHRINK_MARGIN` apart), or None when no pair overlaps. In a container
    (`boundaries`), a particle crossing its wall counts as an overlap too."""
    close = search.pairs_near_contact()
    walls = walls_near_contact(search, boundaries)
    if not len(close) and not len(walls):
        return None
    worst = min(close.smallest_gap(), walls.smallest_gap())
    if worst >= 0:
        return None
    factor = shrink_to_margin(worst, ROUNDOFF_SHRINK_MARGIN)
    shrunk = NeighborSearch(search.positions, search.diameters * factor, search.box,
                            search.periodic)
    note = (f"diameters scaled by 1 - {1 - factor:.1e} to remove round-off overlaps (worst gap "
            f"{worst:.1e})")
    smallest = min(shrunk.pairs_near_contact().smallest_gap(),
                   walls_near_contact(shrunk, boundaries).smallest_gap())
    return RoundoffShrink(factor, shrunk, smallest, note)


def walls_near_contact(search: NeighborSearch, boundaries: Boundaries | None) -> WallRows:
    """Particle–wall pairs that touch, cross or nearly touch (δ ≤ σ_i/2 × (1 +
    `NEAR_CONTACT_SLACK`)) the walls of the container `boundaries` (`calippso.geometry.walls`);
    none in a periodic box (None)."""
    if boundaries is None or boundaries.is_periodic:
        return empty_walls(search.d)
    return wall_rows_within(search.positions, search.diameters, search.box, boundaries,
                            0.0, 1.0 + NEAR_CONTACT_SLACK)
