"""The contact network of a packing as a value, and the final repairs of its forces.

`ContactNetwork` is a value: the contacts between stable particles, their forces, the
rattlers, the wall contacts. The functions here take a configuration (a `NeighborSearch`,
lengths in mean diameters) and a network and return new values, never changing their
arguments; when they repair something they also return the note that says so, for the
run's status. The certificate of a network's jamming point is
`calippso.certification.certificate`.

- `network_key`, `network_balance`: a network's identity and its force balance.
- `touching_network`: at a degenerate jamming point, the touching pairs as the network when
  the LP duals missed contacts.
- `polished_forces`: forces refined by least squares on the equilibrium equations.
- `remove_roundoff_overlaps`: all diameters shrunk by the round-off overlap left at the end.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace

import numpy as np

from .boundaries import Boundaries
from .contacts import force_balance, isostaticity_gap, polish_forces, positive_self_stress
from .neighbors import NEAR_CONTACT_SLACK, NeighborSearch, shrink_to_margin
from .rattlers import remove_rattlers
from .walls import (WallRows, empty_walls, wall_equilibrium_columns, wall_rows_of,
                    wall_rows_within)

__all__ = ["ContactNetwork", "RoundoffShrink", "network_key", "network_balance",
           "wall_contact_geometry", "touching_network", "polished_forces",
           "remove_roundoff_overlaps", "walls_near_contact", "GEOMETRIC_CONTACT_GAP",
           "ROUNDOFF_SHRINK_MARGIN"]

#: Pairs closer than this relative gap count as touching (`touching_network`, and the pairs a
#: guessed network must not leave out, `calippso.certification.certificate`).
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
    walls = wall_contact_geometry(search, network, boundaries)
    return walls.particle, walls.normals, network.wall_forces


def wall_contact_geometry(search: NeighborSearch, network: ContactNetwork,
                          boundaries: Boundaries | None) -> WallRows:
    """The geometry of the network's wall contacts in the configuration of `search`."""
    return wall_rows_of(search.positions, search.diameters, search.box, network.wall_particle,
                        network.wall, () if boundaries is None else boundaries.cylinder_axes)


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
        walls = wall_contact_geometry(search, network, boundaries)
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
