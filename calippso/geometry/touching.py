"""Pairs that touch outside a contact network: zero-force contacts of a degenerate packing.

At a jamming point the contact network holds the forces, and every other pair is open. A
packing can also hold pairs of stable particles (or a stable particle and a wall) that touch
to round-off while carrying no force: the certificate holds with their force at zero, and
they are left out of `JammingResult.contacts`. Partly ordered packings and symmetric
containers make them. Counting contacts from the gaps, as analysis codes do, counts them
too, and finds the packing hyperstatic by their number. This module is the one definition
of such pairs: `JammingResult.touching_pairs`, the summary, ``--json`` and
`calippso.analysis` all read it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .neighbors import NeighborSearch
from .packing import Packing

__all__ = ["TOUCHING_GAP", "Touching", "touching_outside_network"]

#: A pair whose relative gap h = |r_ij|/σ_ij − 1 is at most this touches (round-off of a
#: contact), for a wall δ/(σ_i/2) − 1. Contacts of certified packings close to ~1e-15;
#: the smallest open gaps of jammed packings of 10⁴ particles lie near 1e-7.
TOUCHING_GAP = 1e-10


@dataclass(frozen=True)
class Touching:
    """Pairs that touch but are not in the contact network.

    Attributes
    ----------
    pairs : ndarray, shape (K, 2), int64
        Stable particles (i < j) whose relative gap is at most `TOUCHING_GAP`, not in the
        contacts; sorted.
    pair_gaps : ndarray, shape (K,)
        Their relative gaps h_ij.
    walls : ndarray, shape (L, 2), int64
        (particle, wall) of stable particles touching a wall outside the wall contacts (wall
        numbering of `calippso.geometry.walls`); empty in a periodic box.
    wall_gaps : ndarray, shape (L,)
        Their relative gaps to the wall.
    """

    pairs: np.ndarray
    pair_gaps: np.ndarray
    walls: np.ndarray
    wall_gaps: np.ndarray

    def __len__(self) -> int:
        return int(self.pairs.shape[0] + self.walls.shape[0])


def touching_outside_network(packing: Packing, contacts: np.ndarray, rattlers: np.ndarray,
                             wall_contacts: np.ndarray | None = None,
                             gap: float = TOUCHING_GAP) -> Touching:
    """The pairs of stable particles, and particle–wall pairs, that touch outside a network.

    Parameters
    ----------
    packing : Packing
    contacts : ndarray, shape (M, 2), int
        The network's pairs (any order within a pair).
    rattlers : ndarray, shape (N,), bool
        Pairs with a rattler are never reported.
    wall_contacts : ndarray, shape (W, 2), int, optional
        The network's (particle, wall) contacts.
    gap : float
        Largest relative gap of a touching pair (dimensionless).

    Returns
    -------
    Touching
    """
    from .walls import wall_ids, wall_rows_within

    n = packing.n
    periodic = packing.boundaries.periodic
    cutoff = float(packing.diameters.max()) * (1.0 + gap)
    if packing.box_matrix is not None:
        from .sheared_search import sheared_pairs_within

        close = sheared_pairs_within(packing.positions, packing.diameters, packing.search_cell,
                                     cutoff)
    else:
        search = NeighborSearch(packing.positions, packing.diameters, packing.box,
                                None if periodic.all() else periodic)
        close = search.pairs_within(cutoff)
    contacts = np.sort(np.asarray(contacts, dtype=np.int64).reshape(-1, 2), axis=1)
    stable = ~np.asarray(rattlers, dtype=bool)
    outside = ~np.isin(close.i * n + close.j, contacts[:, 0] * n + contacts[:, 1])
    chosen = outside & stable[close.i] & stable[close.j] & (close.gaps <= gap)
    pairs = np.column_stack([close.i[chosen], close.j[chosen]]).astype(np.int64)
    pair_gaps = close.gaps[chosen]
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    walls = np.zeros((0, 2), np.int64)
    wall_gaps = np.zeros(0)
    if not packing.boundaries.is_periodic:
        rows = wall_rows_within(packing.positions, packing.diameters, packing.box,
                                packing.boundaries, 0.0, 1.0 + gap)
        n_walls = wall_ids(packing.d)
        known = np.zeros(0, np.int64) if wall_contacts is None else (
            np.asarray(wall_contacts, np.int64).reshape(-1, 2) @ np.array([n_walls, 1]))
        keep = (~np.isin(rows.keys(n_walls), known) & stable[rows.particle]
                & (rows.gaps <= gap))
        walls = np.column_stack([rows.particle[keep], rows.wall[keep]]).astype(np.int64)
        wall_gaps = rows.gaps[keep]
    return Touching(pairs[order], pair_gaps[order], walls, wall_gaps)
