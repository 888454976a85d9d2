"""Rattlers: which particles they are, and moving them out of overlaps.

A rattler is a particle held by fewer than d + 1 contacts once the other rattlers are gone
(`remove_rattlers`, a rule on the contact graph alone). The generators use it too, so this
module stands on the geometry base: scipy's LP solver is imported only when
`separate_rattlers` runs.

Rattlers carry no force and do not take part in jamming, but they must not overlap. When the
stable particles move to the jamming point of their contact network (`calippso.certification.newton`), a
rattler that touched its cage can end up overlapping it by the distance the cage moved.
`separate_rattlers` solves one small LP over the rattlers' displacements s,

    maximise t ≤ clearance  subject to  |r_ij| + n_ij·(s_i − s_j) ≥ σ_ij (1 + t),

one row per pair with a rattler that could touch within the displacement bound. By the
Cauchy–Schwarz inequality |r + Δ| ≥ n·(r + Δ) = |r| + n·Δ, so t ≥ 0 leaves every such pair
apart exactly, however large the displacement: the rows are not a linearisation. In a
container, a rattler near a wall adds the row δ' + e_w·s_i ≥ σ_w (1 + t) of `calippso.geometry.walls`
(exact for a flat wall, with the curvature margin for a cylinder).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .neighbors import NeighborSearch
from .periodic import wrap

__all__ = ["remove_rattlers", "separate_rattlers", "RATTLER_REACH", "RATTLER_CLEARANCE"]

#: Largest displacement component of a rattler (mean diameters).
RATTLER_REACH = 1e-4
#: Relative gap the LP aims for between a rattler and its neighbours, when the cage allows.
RATTLER_CLEARANCE = 1e-9


def remove_rattlers(n: int, d: int, i: np.ndarray, j: np.ndarray,
                    wall_particle: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Recursively remove particles with fewer than d + 1 contacts.

    Removing a rattler lowers its neighbours' counts, which may make them rattlers too; the
    removal repeats until every remaining particle has at least d + 1 contacts. A contact
    with a wall counts for its particle (and never goes away: walls are not removed).

    Parameters
    ----------
    n, d : int
        Number of particles and dimension.
    i, j : ndarray, shape (M,)
        Contact pairs.
    wall_particle : ndarray, shape (K,), int, optional
        The particle of every wall contact (`calippso.geometry.walls`); a wall contact is kept
        exactly when its particle is stable.

    Returns
    -------
    rattlers : ndarray, shape (N,), bool
    kept : ndarray, shape (M,), bool
        Contacts between two stable particles.
    """
    rattlers = np.zeros(n, dtype=bool)
    kept = np.ones(i.shape[0], dtype=bool)
    at_walls = (np.zeros(n, dtype=np.int64) if wall_particle is None
                else np.bincount(wall_particle, minlength=n))
    while True:
        counts = (np.bincount(i[kept], minlength=n) + np.bincount(j[kept], minlength=n)
                  + at_walls)
        new = (counts < d + 1) & ~rattlers
        if not new.any():
            return rattlers, kept
        rattlers |= new
        kept &= ~(rattlers[i] | rattlers[j])


def separate_rattlers(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                      rattlers: np.ndarray, reach: float = RATTLER_REACH,
                      clearance: float = RATTLER_CLEARANCE,
                      boundaries=None) -> np.ndarray | None:
    """Positions with the rattlers moved so that no pair involving a rattler overlaps.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Positions (mean diameters).
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    rattlers : ndarray, shape (N,), bool
        The particles that may move; all others stay where they are.
    reach : float
        Bound on each displacement component of a rattler.
    clearance : float
        Target relative gap h = |r|/σ − 1 of every pair with a rattler.
    boundaries : calippso.geometry.boundaries.Boundaries, optional
        The container; None: periodic along every axis.

    Returns
    -------
    ndarray, shape (N, d), or None
        The new positions (wrapped into the box), or None when no placement within `reach`
        is free of overlaps (the rattlers' cages are closed).
    """
    from scipy.optimize import linprog   # the LP solver, only when rattlers must move

    from .walls import empty_walls, wall_rows_within

    n, d = positions.shape
    movable = np.flatnonzero(rattlers)
    if movable.size == 0:
        return positions
    periodic = None if boundaries is None or boundaries.is_periodic else boundaries.periodic
    search = NeighborSearch(positions, diameters, box, periodic)
    span = 2.0 * np.sqrt(d) * reach
    close = search.pairs_within(float(diameters.max()) * (1.0 + clearance) + span)
    involved = rattlers[close.i] | rattlers[close.j]
    close = close.subset(involved & (close.distances <= close.sigma * (1.0 + clearance) + span))
    walls = (empty_walls(d) if periodic is None else
             wall_rows_within(positions, diameters, box, boundaries, span, 1.0 + clearance))
    walls = walls.subset(rattlers[walls.particle])
    if not len(close) and not len(walls):
        return positions
    column = np.full(n, -1, dtype=np.int64)
    column[movable] = d * np.arange(movable.size)
    n_cols = d * movable.size + 1
    normals = close.vectors / close.distances[:, None]
    rows, cols, values = [], [], []
    coordinate = np.arange(d)
    for side, sign in ((close.i, -1.0), (close.j, 1.0)):   # −n·(s_i − s_j) + σ t ≤ |r| − σ
        moves = column[side] >= 0
        rows.append(np.repeat(np.flatnonzero(moves), d))
        cols.append((column[side][moves, None] + coordinate).ravel())
        values.append(sign * normals[moves].ravel())
    rows.append(np.arange(len(close)))
    cols.append(np.full(len(close), n_cols - 1))
    values.append(close.sigma)
    # a wall row: −e_w·s_i + σ_w t ≤ δ' − σ_w
    wall_row, axis = np.nonzero(walls.normals)
    rows += [len(close) + wall_row, len(close) + np.arange(len(walls))]
    cols += [column[walls.particle[wall_row]] + axis, np.full(len(walls), n_cols - 1)]
    values += [-walls.normals[wall_row, axis], walls.sigma]
    distances = walls.row_distances(reach)
    matrix = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows),
                                                     np.concatenate(cols))),
                           shape=(len(close) + len(walls), n_cols))
    cost = np.zeros(n_cols)
    cost[-1] = -1.0
    bounds = [(-reach, reach)] * (n_cols - 1) + [(-1.0, clearance)]
    upper = np.concatenate([close.distances - close.sigma, distances - walls.sigma])
    answer = linprog(cost, A_ub=matrix, b_ub=upper, bounds=bounds,
                     method="highs", options={"primal_feasibility_tolerance": 1e-10,
                                              "dual_feasibility_tolerance": 1e-10})
    if answer.status != 0 or answer.x[-1] < 0:
        return None
    moved = positions.copy()
    moved[movable] += answer.x[:-1].reshape(movable.size, d)
    return wrap(moved, box, periodic)
