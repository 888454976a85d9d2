"""Close the floppy modes of a hypostatic network: the start of a pivot path from too few contacts.

A network C of M contacts between N_s stable particles with M = d (N_s − 1) + 1 − F, F > 0
(a quench stopped early, a hint that misses contacts), leaves an F-dimensional family of
motions that keep every contact closed. Γ grows along them until pairs outside C close, one
per floppy mode, and then the network is isostatic and `calippso.certification.pivots` takes over. Each
closure:

1. **Direction.** The least displacement t with dΓ = 1 that keeps every contact closed,
   J_x t = 1 (Φ_c = |r_c|²/σ_c² − Γ, so dΦ_c = J_x t − dΓ): the solution of

       [ I    J_xᵀ ] [ t ]   [ 0 ]
       [ J_x  0    ] [ λ ] = [ 1 ],

   a sparse symmetric system whose factors are refined against it (`pivots.geometry.least_norm_solve`).
   It is singular when the contacts hold a self-stress, and then Γ cannot grow along the
   floppy modes at first order: the closure stops there.
2. **Ratio test.** The first pair of stable particles outside C to close along t
   (`pivots.geometry.find_closing_pairs`, Harris's choice among near ties).
3. **Correct.** C' = C ∪ {k}. From the predicted point x + δ t, least-norm Gauss–Newton
   steps with the same kind of system bring every contact of C' back to contact at the
   inflation 1 + δ; the last closure (C' isostatic) is solved by Newton with Γ free
   (`calippso.certification.newton.refine_isostatic`), which also gives its forces. The point is kept when
   no other pair overlaps there and the rattlers can be cleared of their cages; otherwise
   the next pair of the ratio test is tried.

Between closures the inflation reached is absorbed into the diameters (σ √Γ), so that every
contact has Φ_c = 0 at Γ = 1. Particles with d contacts or fewer are rattlers (removed
recursively), as in the rest of the package; they do not move with the modes and are cleared
out of the way when a moved cage overlaps them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from ..geometry.contacts import isostaticity_gap
from ..geometry.neighbors import NeighborSearch
from ..network import NEWTON_OVERLAP_TOLERANCE
from .newton import Refinement, network_jacobian, refine_isostatic
from ..geometry.packing import minimum_image
from .pivots.geometry import (NEAR_GAP, RATIO_CANDIDATES, clear_rattlers, find_closing_pairs,
                              least_norm_solve, onto_contacts, outside_pairs)
from .pivots.vertex import DEGENERATE_STEP
from ..geometry.rattlers import remove_rattlers

__all__ = ["Closure", "close_floppy_modes", "MAX_CLOSURES"]

#: Floppy modes closed at most: a network that misses more contacts is not a few contacts
#: off (each closure costs two sparse factorisations).
MAX_CLOSURES = 64


@dataclass(frozen=True, eq=False)
class Closure:
    """An isostatic network reached by closing the floppy modes of a hypostatic one, at its
    Newton point.

    Attributes
    ----------
    i, j : ndarray, shape (M,), int64
        Contacts between stable particles, i < j, M = d (N_s − 1) + 1.
    rattlers : ndarray, shape (N,), bool
    refinement : Refinement
        The Newton point of the network (positions, diameters σ √Γ, forces; its forces need
        not be positive: `calippso.certification.pivots` starts there).
    closed : tuple of (int, int)
        The pairs that closed, in order.
    seconds : float
        Wall time.
    """

    i: np.ndarray
    j: np.ndarray
    rattlers: np.ndarray
    refinement: Refinement
    closed: tuple[tuple[int, int], ...]
    seconds: float


def close_floppy_modes(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                       i: np.ndarray, j: np.ndarray,
                       max_closures: int = MAX_CLOSURES) -> tuple[Closure | None, str]:
    """Close the floppy modes of a hypostatic network, with Γ growing (module doc).

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (mean diameters), with the network's pairs near contact.
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    i, j : ndarray, shape (M,), int
        The network, i < j; particles left with d contacts or fewer become rattlers.
    max_closures : int
        Floppy modes closed at most.

    Returns
    -------
    (Closure or None, str)
        The isostatic network at its Newton point, and ""; or None and why the closure
        stopped: the network is not hypostatic, its contacts cannot all close at the start
        or another pair overlaps there, Γ cannot grow along the modes (a self-stress), no
        pair near contact closes, or a cage closed on its rattler.
    """
    began = time.perf_counter()
    n, d = positions.shape
    rattlers, kept = remove_rattlers(n, d, np.asarray(i, np.int64), np.asarray(j, np.int64))
    i, j, stable = np.asarray(i, np.int64)[kept], np.asarray(j, np.int64)[kept], ~rattlers
    missing = -isostaticity_gap(i.shape[0], int(stable.sum()), d)
    if not 0 < missing <= max_closures or stable.sum() < 2:
        return None, (f"the network is not hypostatic by 1 to {max_closures} contacts "
                      f"({missing} missing)")
    gamma = float(np.mean(_phi(positions, diameters, box, i, j) + 1.0))
    scaled = diameters * np.sqrt(gamma)
    closed_at = onto_contacts(positions, scaled, box, i, j, stable, 1.0)
    if closed_at is None:
        return None, "the network's contacts cannot all close at the start"
    moved = closed_at[0]
    search = NeighborSearch(moved, scaled, box)
    if np.any(outside_pairs(search, i * n + j, stable, NEAR_GAP).gaps
              < -NEWTON_OVERLAP_TOLERANCE):
        return None, "another pair overlaps where the network's contacts close"
    closed: list[tuple[int, int]] = []
    while True:
        step, failure = _close_one(search, i, j, stable)
        if step is None:
            return None, failure
        search, i, j, pair, refinement = step
        closed.append(pair)
        if refinement is not None:
            return Closure(i, j, rattlers, refinement, tuple(closed),
                           time.perf_counter() - began), ""


def _close_one(search: NeighborSearch, i: np.ndarray, j: np.ndarray, stable: np.ndarray):
    """Follow the least-displacement floppy mode with dΓ = 1 until the first pair closes.

    Returns
    -------
    ((search, i, j, pair, Refinement or None) or None, str)
        The configuration with the closed pair added (diameters σ √Γ), and the Newton point
        when the network became isostatic; or None and why.
    """
    n, d = search.positions.shape
    direction = _least_floppy_mode(search, i, j, stable)
    if direction is None:
        return None, "Γ cannot grow along the floppy modes (the contacts hold a self-stress)"
    ratio_test = find_closing_pairs(search, i * n + j, stable, direction)
    if ratio_test is None:
        return None, "the floppy modes close no pair near contact"
    near, steps, candidates = ratio_test
    for closing in candidates[:RATIO_CANDIDATES]:
        step = float(steps[closing])
        predicted = search.positions + step * direction
        i_new, j_new = np.append(i, near.i[closing]), np.append(j, near.j[closing])
        order = np.lexsort((j_new, i_new))
        i_new, j_new = i_new[order], j_new[order]
        if isostaticity_gap(i_new.shape[0], int(stable.sum()), d) == 0:
            refinement = refine_isostatic(predicted, search.diameters, search.box, i_new,
                                          j_new, stable)
            if refinement is None:
                continue
            growth = float(np.mean(refinement.diameters / search.diameters)) - 1.0
            positions, diameters = refinement.positions, refinement.diameters
        else:
            refinement, growth = None, np.sqrt(1.0 + step) - 1.0
            diameters = search.diameters * np.sqrt(1.0 + step)
            closed_at = onto_contacts(predicted, diameters, search.box, i_new, j_new, stable,
                                      1.0)
            if closed_at is None:
                continue
            positions = closed_at[0]
        if growth < -DEGENERATE_STEP:
            continue
        moved = NeighborSearch(positions, diameters, search.box)
        if np.any(outside_pairs(moved, i_new * n + j_new, stable, NEAR_GAP).gaps
                  < -NEWTON_OVERLAP_TOLERANCE):
            continue
        cleared = clear_rattlers(moved, stable)
        if cleared is None:
            return None, "a rattler's cage closed along the floppy modes"
        if cleared is not moved.positions:   # rattlers moved out of the way
            moved = NeighborSearch(cleared, diameters, search.box)
            if refinement is not None:
                refinement = replace(refinement, positions=cleared)
        pair = (int(near.i[closing]), int(near.j[closing]))
        return (moved, i_new, j_new, pair, refinement), ""
    return None, "no closing pair gave a point without overlap"


def _phi(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray, i: np.ndarray,
         j: np.ndarray) -> np.ndarray:
    """Φ_c + Γ = |r_c|²/σ_c² of the pairs, shape (M,)."""
    vectors = minimum_image(positions[i] - positions[j], box)
    sigma = 0.5 * (diameters[i] + diameters[j])
    return np.einsum("md,md->m", vectors, vectors) / sigma**2 - 1.0


def _position_jacobian(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                       i: np.ndarray, j: np.ndarray, stable: np.ndarray) -> sp.csr_matrix:
    """J_x: the contact Jacobian without its Γ column, shape (M, d (N_s − 1))."""
    vectors = minimum_image(positions[i] - positions[j], box)
    full = network_jacobian(vectors, 0.5 * (diameters[i] + diameters[j]), i, j, stable)
    return full[:, :-1].tocsr()


def _least_floppy_mode(search: NeighborSearch, i: np.ndarray, j: np.ndarray,
                       stable: np.ndarray) -> np.ndarray | None:
    """The least displacement per unit of Γ that keeps every contact closed, shape (N, d)
    (zero for the pinned particle and the rattlers); None when Γ cannot grow (singular)."""
    n, d = search.positions.shape
    jacobian = _position_jacobian(search.positions, search.diameters, search.box, i, j, stable)
    solved = least_norm_solve(jacobian, np.ones(i.shape[0]))
    if solved is None:
        return None
    mode = np.zeros((n, d))
    mode[np.flatnonzero(stable)[1:]] = solved[0].reshape(-1, d)
    return mode

