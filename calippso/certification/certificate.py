"""The certificate of a jamming point: an isostatic network solved by Newton, with every force
positive and no other pair overlapping.

`certify_network` is the last step of the certification path (`calippso.certification`): a
network guessed from the input, settled by network first, or read from an LP's duals is
accepted only with this certificate. `overlaps_outside` is its test for pairs outside the
network.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..geometry.boundaries import Boundaries
from ..geometry.contact_network import (GEOMETRIC_CONTACT_GAP, ContactNetwork,
                                        network_balance, wall_contact_geometry,
                                        walls_near_contact)
from ..geometry.neighbors import NeighborSearch, Pairs
from ..geometry.rattlers import separate_rattlers
from ..geometry.walls import WallRows, wall_ids
from .newton import NEWTON_FAILED, Refinement, refine_isostatic

__all__ = ["Certified", "certify_network", "overlaps_outside", "NEWTON_OVERLAP_TOLERANCE"]

#: A pair outside the contact network may overlap by at most this relative gap at a Newton
#: solution (round-off); more means the network is not the jammed one.
NEWTON_OVERLAP_TOLERANCE = 1e-12


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
    walls = wall_contact_geometry(search, network, boundaries)
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
