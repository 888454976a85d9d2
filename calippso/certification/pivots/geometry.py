"""The exact geometry under a pivot: the ratio test and the refined solves.

`find_closing_pairs` is the ratio test along a floppy mode (Harris's choice among near ties),
`outside_pairs` the pairs it reads; `refined_solve` refines a solve with stored factors
against the exact matrix; `clear_rattlers` moves rattlers out of the way of moved cages.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from ...geometry.neighbors import NeighborSearch, Pairs
from ..certificate import NEWTON_OVERLAP_TOLERANCE
from ..newton import MAX_REFINEMENTS, REFINEMENT_TOLERANCE, Refinement
from ...geometry.rattlers import separate_rattlers
from ..sparse_lu import Factors

__all__ = ["find_closing_pairs", "closing_rates", "outside_pairs",
           "refined_solve", "clear_rattlers", "rattlers_out_of_the_way",
           "NEAR_GAP", "NEAR_GAP_WIDENING", "MAX_NEAR_GAP", "RATTLER_REACH",
           "HARRIS_SLACK", "RATIO_CANDIDATES"]

#: Pairs of stable particles closer than this relative gap enter the ratio test; a step that
#: could close a pair beyond it reads the pairs `NEAR_GAP_WIDENING` times farther.
NEAR_GAP = 1e-3
NEAR_GAP_WIDENING = 10.0
#: Largest relative gap read by the ratio test: a floppy mode that closes no pair within it
#: is not a small correction of the network.
MAX_NEAR_GAP = 0.3
#: Largest displacement component of a rattler moved out of the way of its moved cage
#: (mean diameters): a rattler held by a few near pairs is pushed along by them, by up to a
#: few 1e-3 over a pivot.
RATTLER_REACH = 1e-2
#: Harris's ratio test treats pairs within this much of Φ = |r|²/σ² − Γ (about twice the
#: relative gap) as closing together: well inside the overlap tolerance of the certificate.
HARRIS_SLACK = 1e-12
#: Pairs of the ratio test tried in turn, when Newton's vertex for the first one overlaps
#: another pair (the curve is not the line of the prediction).
RATIO_CANDIDATES = 4


def clear_rattlers(search: NeighborSearch, stable: np.ndarray) -> np.ndarray | None:
    """The positions of `search` with the rattlers (not `stable`) moved out of the cages that
    overlap them (`calippso.geometry.rattlers.separate_rattlers`, within `RATTLER_REACH`), shape
    (N, d); the positions themselves when nothing overlaps; None when a cage has closed on
    its rattler."""
    close = search.pairs_near_contact()
    with_rattler = ~stable[close.i] | ~stable[close.j]
    overlapping = with_rattler & (close.gaps < -NEWTON_OVERLAP_TOLERANCE)
    if not np.any(overlapping):
        return search.positions
    # the rattlers that overlap move first (a small LP), all rattlers if they cannot
    involved = np.zeros_like(stable)
    involved[close.i[overlapping]] = involved[close.j[overlapping]] = True
    for movable in (involved & ~stable, ~stable):
        separated = separate_rattlers(search.positions, search.diameters, search.box,
                                      movable, reach=RATTLER_REACH)
        if separated is not None:
            return separated
    return None


def rattlers_out_of_the_way(search: NeighborSearch, refined: Refinement,
                             stable: np.ndarray) -> Refinement | None:
    """`refined` (the configuration of `search`) with its rattlers cleared of the moved cages
    (`clear_rattlers`); None when a cage has closed on its rattler."""
    cleared = clear_rattlers(search, stable)
    return None if cleared is None else replace(refined, positions=cleared)


def refined_solve(matrix: sp.csr_matrix, factors: Factors, rhs: np.ndarray,
                  normwise: bool = False) -> np.ndarray | None:
    """The solution of matrix x = rhs from factors of a nearby matrix, by iterative
    refinement to a componentwise backward error of `REFINEMENT_TOLERANCE` (as
    `calippso.certification.newton` does for the forces); None when `MAX_REFINEMENTS` steps do not reach it.

    With `normwise`, the backward error is that of the largest row instead: for a solution
    that vanishes on most rows' support (a localised null vector), where those rows hold
    round-off of nothing."""
    magnitudes = abs(matrix)
    solution = factors.solve(rhs)
    for _ in range(MAX_REFINEMENTS + 1):
        if not np.all(np.isfinite(solution)):
            return None
        remainder = rhs - matrix @ solution
        error, scale = np.abs(remainder), magnitudes @ np.abs(solution) + np.abs(rhs)
        if (error.max(initial=0.0) <= REFINEMENT_TOLERANCE * scale.max(initial=0.0)
                if normwise else np.all(error <= REFINEMENT_TOLERANCE * scale)):
            return solution
        solution = solution + factors.solve(remainder)
    return None


def find_closing_pairs(search: NeighborSearch, keys: np.ndarray, stable: np.ndarray,
                       mode: np.ndarray) -> tuple[Pairs, np.ndarray, np.ndarray] | None:
    """The ratio test: the pairs of stable particles outside a network (pair keys
    i N + j, shape (M,)) that close along its floppy mode, in the order to try them
    (Harris's choice first, `_harris_choice`, then by step and key).

    Pairs within `NEAR_GAP` of contact are read first, farther ones (up to `MAX_NEAR_GAP`,
    and within half the smallest periodic side) while the first step could close a pair
    beyond them (`_reach`).

    Parameters
    ----------
    mode : ndarray, shape (N, d)
        The displacement of every particle per unit inflation (mean diameters): the floppy
        mode normalised to dΓ = 1, so that the steps are inflations (Γ relative to the
        inflation of `search`'s diameters).

    Returns
    -------
    (Pairs, ndarray, ndarray) or None
        The pairs read, their steps δ_q (+inf for pairs that open), and the indices of the
        closing pairs in the order to try; None when no pair closes.
    """
    n = stable.shape[0]
    # pairs are read within half the periodic box (a minimum image), NEAR_GAP short of it
    widest = min(MAX_NEAR_GAP,
                 search.half_period / float(search.diameters.max()) - 1.0 - NEAR_GAP)
    near_gap = NEAR_GAP
    while True:
        near = outside_pairs(search, keys, stable, near_gap)
        steps = _closing_steps(near, mode)
        order = np.lexsort((near.i * n + near.j, steps))   # smallest step, then Bland
        order = order[np.isfinite(steps[order])]
        if order.size and _reach(steps[order[0]], mode, search) < near_gap:
            break
        if near_gap >= widest:
            return None
        near_gap = min(near_gap * NEAR_GAP_WIDENING, widest)
    first = _harris_choice(near, mode, steps, order)
    return near, steps, np.concatenate([[first], order[order != first]])


def _harris_choice(pairs: Pairs, mode: np.ndarray, steps: np.ndarray,
                   order: np.ndarray) -> int:
    """The pair that closes first, by Harris's ratio test: among the pairs that close before
    the smallest step relaxed by `HARRIS_SLACK` (pairs within round-off of contact close
    together), the one that closes fastest along the mode, so that the new network is the
    best conditioned; ties to the smallest pair key (`order` is by step, then key)."""
    rates = -closing_rates(pairs.subset(order), mode)
    phi = (pairs.distances[order] / pairs.sigma[order]) ** 2 - 1.0
    relaxed = float(np.min((np.maximum(phi, 0.0) + HARRIS_SLACK) / rates))
    within = steps[order] <= relaxed
    return int(order[np.flatnonzero(within)[np.argmax(rates[within])]])


def closing_rates(pairs: Pairs, mode: np.ndarray) -> np.ndarray:
    """dΦ_q per unit inflation along a mode normalised to dΓ = 1, shape (P,):
    Φ_q = |r_q|²/σ_q² − Γ (negative: closing)."""
    relative = mode[pairs.i] - mode[pairs.j]
    return 2.0 * np.einsum("pd,pd->p", pairs.vectors, relative) / pairs.sigma**2 - 1.0


def _closing_steps(pairs: Pairs, mode: np.ndarray) -> np.ndarray:
    """The step δ_q = Φ_q / (−dΦ_q/dstep) at which each pair closes along the mode
    (linearised), shape (P,); +inf for pairs that open. Pairs that already touch close at 0."""
    rates = closing_rates(pairs, mode)
    phi = (pairs.distances / pairs.sigma) ** 2 - 1.0
    steps = np.full(len(pairs), np.inf)
    closing = rates < 0
    steps[closing] = np.maximum(phi[closing], 0.0) / -rates[closing]
    return steps


def _reach(step: float, mode: np.ndarray, search: NeighborSearch) -> float:
    """An upper bound on how much a relative gap can shrink over a step along the mode: the
    growth of the diameters plus twice the largest move, relative to the smallest
    diameter."""
    largest_move = float(np.sqrt(np.einsum("nd,nd->n", mode, mode)).max(initial=0.0))
    return step * (0.5 + 2.0 * largest_move / float(search.diameters.min()))


def outside_pairs(search: NeighborSearch, keys: np.ndarray, stable: np.ndarray,
                  near_gap: float) -> Pairs:
    """The pairs of `stable` particles within `near_gap` of contact that are not contacts
    (pair keys i N + j, shape (M,))."""
    n = stable.shape[0]
    pairs = search.pairs_within(float(search.diameters.max()) * (1.0 + near_gap))
    outside = (~np.isin(pairs.i * n + pairs.j, keys) & stable[pairs.i]
               & stable[pairs.j] & (pairs.gaps < near_gap))
    return pairs.subset(outside)
