"""The pivot path: release a contact with a non-positive force, follow the floppy mode, close
the first pair, and repeat until every force is positive (`pivot_to_jamming`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from ...geometry.neighbors import NeighborSearch, PairList
from ..certificate import NEWTON_OVERLAP_TOLERANCE
from ..newton import (MIN_FORCE_RATIO, NEWTON_FAILED, Refinement, network_jacobian,
                      refine_isostatic)
from ...geometry.packing import minimum_image
from ...geometry.rattlers import remove_rattlers
from ..sparse_lu import Factors, factorize, tally
from .cages import CAGE_GAP, CageClosure, closing_cages
from .geometry import (NEAR_GAP, RATIO_CANDIDATES, closing_rates, find_closing_pairs,
                       outside_pairs, rattlers_out_of_the_way, refined_solve)
from .vertex import DEGENERATE_STEP, Basis, PivotPath, Swap, Vertex

__all__ = ["pivot_to_jamming", "PivotHook", "MAX_PIVOTS", "REJOIN_TRIES", "CAGE_CLOSED",
           "SINGULAR_RELEASE", "LEAVING_TRIES"]

#: Called after every pivot with the number of pivots taken, the pivot, the vertex it
#: reached (its Newton solution) and that vertex's stable particles.
PivotHook = Callable[[int, Swap, Refinement, np.ndarray], None]
#: Pivots taken at most before the path gives up (a network a few contacts off takes a few
#: to a few tens).
MAX_PIVOTS = 500
#: Rattlers whose cage closes before the ratio test's pair tried in turn (earliest first)
#: as the pivot's entering pairs: each try is a Newton solve with new unknowns.
REJOIN_TRIES = 2
#: Why a pivot failed when a rattler's cage closed on it (the pivot is then tried again with
#: the particles that the release leaves with d contacts kept in the network).
CAGE_CLOSED = "a rattler's cage closed along the floppy mode"
#: Why a pivot failed when the network without the released contact is singular (Γ cannot
#: grow along its floppy modes).
SINGULAR_RELEASE = "the network without the released contact is singular"
#: Contacts with non-positive forces tried in turn (most negative first) when releasing one
#: gives no pivot: its released network is singular (a floppy cluster held by a redundant
#: contact), or its floppy mode closes no pair. Any of them may leave: Γ grows along each.
LEAVING_TRIES = 5
#: The release opens a floppy mode along which Γ grows only when the Γ component of
#: J⁻¹ e_c (minus the released force) is above this, relative to the largest component:
#: below, it is round-off of a zero (a redundant contact, a singular released network).
SINGULAR_GROWTH = 1e-13
#: The pair queries of a pivot reach relative gaps up to the cage test's (the ratio test's
#: first reading, `NEAR_GAP`, and the pairs near contact lie within it; its widened
#: readings fall back to the tree) ...
LISTED_QUERY_GAP = CAGE_GAP
#: ... and the path keeps every pair within twice that of a vertex, so that the list serves
#: until a particle has moved by a quarter of it (rattlers pushed by their cages move most,
#: up to `geometry.RATTLER_REACH` a pivot).
LISTED_GAP = 2.0 * CAGE_GAP


def pivot_to_jamming(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                     i: np.ndarray, j: np.ndarray, rattlers: np.ndarray,
                     refined: Refinement | None = None, max_pivots: int = MAX_PIVOTS,
                     time_limit: float | None = None, on_pivot: PivotHook | None = None
                     ) -> tuple[PivotPath | None, str]:
    """Pivot from an isostatic network to the jamming point (module doc).

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (mean diameters), at the Newton point of the network when `refined` is None.
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    i, j : ndarray, shape (M,), int
        An isostatic network between stable particles, M = d (N_s − 1) + 1, i < j.
    rattlers : ndarray, shape (N,), bool
    refined : Refinement, optional
        Newton's solution of the network from `positions`, when already computed; without
        it Newton solves the network.
    max_pivots : int
        Pivots taken at most.
    time_limit : float, optional
        Seconds the path may take: no pivot starts after them (the one under way ends).
    on_pivot : PivotHook, optional
        Called after every pivot (a run's progress: `calippso.stages.newton_stage.pivot_progress`).

    Returns
    -------
    (PivotPath or None, str)
        The path's end, with positive forces and no overlap (`PivotPath.jammed`), and "";
        or where it stopped and why: the network became singular, a floppy mode closes no
        pair near contact, a rattler's cage closed, the path returned to a network it had
        left, `max_pivots` were taken or `time_limit` passed (a `PivotPath` with
        ``jammed=False`` once a pivot was made, None when the start itself is refused:
        another pair overlaps there, or Newton cannot solve its network).
    """
    with tally() as cost:
        path, failure = _follow(positions, diameters, box, i, j, rattlers, refined,
                                max_pivots, time_limit, on_pivot)
    return (None if path is None else replace(path, cost=cost)), failure


def _follow(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray, i: np.ndarray,
            j: np.ndarray, rattlers: np.ndarray, refined: Refinement | None, max_pivots: int,
            time_limit: float | None, on_pivot: PivotHook | None
            ) -> tuple[PivotPath | None, str]:
    """`pivot_to_jamming` without its tally."""
    began = time.perf_counter()
    i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
    stable = ~np.asarray(rattlers, dtype=bool)
    start_positions, start_diameters = positions, diameters
    swaps: list[Swap] = []
    if refined is None:
        refined = refine_isostatic(positions, diameters, box, i, j, stable)
    if refined is None:
        return None, NEWTON_FAILED
    refined = rattlers_out_of_the_way(
        NeighborSearch(refined.positions, refined.diameters, box), refined, stable)
    if refined is None:
        return None, "a rattler overlaps its cage at the start"
    basis = (None if refined.factorization is None
             else Basis(*refined.factorization, stable))
    vertex = Vertex(i, j, stable, refined, basis)
    seen = {_network_digest(vertex)}
    degenerate = False
    pair_list = None

    def ended(jammed: bool) -> PivotPath:
        return PivotPath(vertex.i, vertex.j, ~vertex.stable,
                         _from_start(vertex.refinement, start_positions, start_diameters, box,
                                     vertex.stable),
                         tuple(swaps), time.perf_counter() - began, jammed)

    while True:
        search, pair_list = _search_at(vertex.refinement, box, pair_list)
        overlapping = int(np.sum(outside_pairs(search, vertex.keys, vertex.stable, NEAR_GAP).gaps
                                 < -NEWTON_OVERLAP_TOLERANCE))
        if overlapping:
            return None, f"{overlapping} other pair(s) overlap"
        if vertex.refinement.positive:
            return ended(True), ""
        if len(swaps) >= max_pivots:
            return ended(False), f"no jamming point within {max_pivots} pivots"
        if time_limit is not None and time.perf_counter() - began > time_limit:
            return ended(False), f"no jamming point within {time_limit:g} s of pivots"
        pivot_began = time.perf_counter()
        for released in _leaving_contacts(vertex, bland=degenerate)[:LEAVING_TRIES]:
            step, failure = _pivot(search, vertex, int(released))
            if step is None and failure == CAGE_CLOSED:
                # the particles the release left with d contacts stay in the network
                step, failure = _pivot(search, vertex, int(released), attached=True)
            if step is not None:
                break
        if step is None:
            return (ended(False) if swaps else None), failure
        next_vertex, swap = step
        degenerate = swap.growth <= DEGENERATE_STEP
        if not degenerate:   # Γ grew: no network seen so far can come back
            seen.clear()
        digest = _network_digest(next_vertex)
        if digest in seen:
            return ended(False), "the path returned to a network it had left (cycling)"
        seen.add(digest)
        forces = next_vertex.refinement.forces
        swaps.append(replace(swap, seconds=time.perf_counter() - pivot_began,
                             non_positive=int(np.count_nonzero(
                                 forces <= MIN_FORCE_RATIO * float(forces.max())))))
        vertex = next_vertex
        if on_pivot is not None:
            on_pivot(len(swaps), swaps[-1], vertex.refinement, vertex.stable)


def _pivot(search: NeighborSearch, vertex: Vertex, released: int,
           attached: bool = False) -> tuple[tuple[Vertex, Swap] | None, str]:
    """Release contact `released` of `vertex`, follow the floppy mode, close the first pair.

    Parameters
    ----------
    attached : bool
        Keep the particles that the release leaves with d contacts in the network, held by
        them, while the mode is followed (each still adds as many unknowns as contacts, so
        there is still one floppy mode): their cage may close on them, and the pair that
        closes gives them d + 1 contacts again. Those still left with d contacts at the new
        vertex (whose forces vanish there) become rattlers then.

    Returns
    -------
    ((next vertex, swap) or None, str)
    """
    n, d = vertex.refinement.positions.shape
    keep = np.ones(vertex.i.shape[0], dtype=bool)
    keep[released] = False
    if attached:
        i_a, j_a, stable = vertex.i[keep], vertex.j[keep], vertex.stable
    else:
        ratt, kept = remove_rattlers(n, d, vertex.i[keep], vertex.j[keep])
        i_a, j_a, stable = vertex.i[keep][kept], vertex.j[keep][kept], ~ratt
    in_place = np.array_equal(stable, vertex.stable)
    if in_place:   # same unknowns: the row of the released contact is swapped in place
        rows_i, rows_j, swap_row = vertex.i, vertex.j, released
        basis, swapped = vertex.basis, vertex.swapped
    else:   # rattlers left with their contacts: new unknowns, the swapped row last
        rows_i, rows_j, swap_row = np.append(i_a, 0), np.append(j_a, 0), i_a.shape[0]
        basis, swapped = None, ()
    if basis is not None and not basis.fits(stable):
        basis, swapped = None, ()
    mode = _floppy_mode(search, rows_i, rows_j, stable, swap_row, basis, swapped, in_place)
    if mode is None:
        return None, SINGULAR_RELEASE
    direction, made = mode
    if made is not None:   # new factors: the basis of this pivot (and the next ones)
        basis, swapped = made, ()
    c_i, c_j = int(vertex.i[released]), int(vertex.j[released])
    if stable[c_i] and stable[c_j]:
        c_pair = search.pairs_of(np.array([c_i]), np.array([c_j]))
        if closing_rates(c_pair, direction)[0] <= 0:
            return None, "the released contact does not open along its floppy mode"
    ratio_test = find_closing_pairs(search, i_a * n + j_a, stable, direction)
    first_step = np.inf if ratio_test is None else float(ratio_test[1][ratio_test[2][0]])
    released_pair = (c_i, c_j)
    for cage in closing_cages(search, stable, direction, first_step)[:REJOIN_TRIES]:
        entered = _enter_cage(search, vertex, i_a, j_a, stable, direction, cage, released_pair)
        if entered is not None:
            return entered, ""
    if ratio_test is None:
        return None, "the floppy mode closes no pair near contact"
    near, steps, candidates = ratio_test
    positions = vertex.refinement.positions
    diameters = vertex.refinement.diameters
    next_swapped = tuple(sorted(set(swapped) | {swap_row}))
    for closing in candidates[:RATIO_CANDIDATES]:
        predicted = positions + steps[closing] * direction
        i_new, j_new = rows_i.copy(), rows_j.copy()
        i_new[swap_row], j_new[swap_row] = near.i[closing], near.j[closing]
        factors = None if basis is None else basis.factors_for(
            _jacobian_at(predicted, diameters, search.box, i_new, j_new, stable), next_swapped)
        refined = refine_isostatic(predicted, diameters, search.box, i_new, j_new, stable,
                                   factors=factors)
        reached = _vertex_at(search, vertex, refined, i_new, j_new, stable, attached)
        if reached == CAGE_CLOSED:   # a later pair of the ratio test would close it too
            return None, CAGE_CLOSED
        if isinstance(reached, str):
            continue
        i_new, j_new, now_stable, refined, growth = reached
        if refined.factorization is not None:
            next_basis, next_swaps = Basis(*refined.factorization, stable), ()
        elif basis is not None and basis.gamma_row is None:
            next_basis, next_swaps = basis, next_swapped
        else:   # the factors of K serve this pivot only: the next starts from a Jacobian
            next_basis, next_swaps = None, ()
        if not np.array_equal(now_stable, stable):   # the rows of the new rattlers left
            next_basis, next_swaps = None, ()
        candidate = Vertex(i_new, j_new, now_stable, refined, next_basis, next_swaps)
        swap = Swap(released_pair, (int(near.i[closing]), int(near.j[closing])), growth,
                    int(np.count_nonzero(~now_stable & vertex.stable)))
        return (candidate, swap), ""
    return None, "Newton found no vertex without overlap along the floppy mode"


def _vertex_at(search: NeighborSearch, vertex: Vertex, refined: Refinement | None,
               i_new: np.ndarray, j_new: np.ndarray, stable: np.ndarray, attached: bool
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Refinement, float] | str:
    """The vertex that Newton's solution `refined` of network (i_new, j_new) over the
    `stable` particles makes: its contacts and stable particles once the particles left with
    d contacts are rattlers again (`attached`), its rattlers out of the way of the moved
    cages, and its growth over `vertex` (≥ 0).

    Returns
    -------
    (i, j, stable, Refinement, float) or str
        The vertex, or why there is none: Newton failed, Γ fell, another pair overlaps, or
        a cage closed on its rattler (`CAGE_CLOSED`).
    """
    n, d = search.positions.shape
    if refined is None:
        return NEWTON_FAILED
    growth = float(np.mean(refined.diameters / vertex.refinement.diameters)) - 1.0
    if growth < -DEGENERATE_STEP:
        return "the inflation fell"
    now_rattlers, kept = remove_rattlers(n, d, i_new, j_new)
    if attached and not kept.all():   # left with d contacts: zero forces, rattlers now
        i_new, j_new = i_new[kept], j_new[kept]
        refined = replace(refined, forces=refined.forces[kept])
    now_stable = ~now_rattlers
    moved = NeighborSearch(refined.positions, refined.diameters, search.box,
                           pair_list=search.listed)
    if np.any(outside_pairs(moved, i_new * n + j_new, now_stable,
                            NEAR_GAP).gaps < -NEWTON_OVERLAP_TOLERANCE):
        return "another pair overlaps"
    separated = rattlers_out_of_the_way(moved, refined, now_stable)
    if separated is None:
        return CAGE_CLOSED
    return i_new, j_new, now_stable, separated, max(growth, 0.0)


def _enter_cage(search: NeighborSearch, vertex: Vertex, i_a: np.ndarray, j_a: np.ndarray,
                stable: np.ndarray, direction: np.ndarray, cage: CageClosure,
                released: tuple[int, int]) -> tuple[Vertex, Swap] | None:
    """The pivot whose entering pairs are a closing cage's (`cages.closing_cages`): the
    rattler joins the released network (i_a, j_a over `stable`, one floppy mode) with its d + 1
    closing pairs, and Newton solves that isostatic network from the point of the mode where
    the cage closes. None when Newton finds no vertex without overlap there."""
    predicted = vertex.refinement.positions + cage.step * direction
    predicted[cage.rattlers] += cage.displacements
    i_new, j_new = np.concatenate([i_a, cage.i]), np.concatenate([j_a, cage.j])
    joined = stable.copy()
    joined[cage.rattlers] = True
    refined = refine_isostatic(predicted, vertex.refinement.diameters, search.box,
                               i_new, j_new, joined)
    reached = _vertex_at(search, vertex, refined, i_new, j_new, joined, attached=False)
    if isinstance(reached, str):
        return None
    i_new, j_new, now_stable, refined, growth = reached
    basis = None if refined.factorization is None else Basis(*refined.factorization, joined)
    if not np.array_equal(now_stable, joined):
        basis = None
    swap = Swap(released, (int(cage.i[0]), int(cage.j[0])), growth,
                int(np.count_nonzero(~stable & vertex.stable)), rejoined=int(cage.rattlers.size))
    return Vertex(i_new, j_new, now_stable, refined, basis), swap


def _search_at(refinement: Refinement, box: np.ndarray,
               pair_list: PairList | None) -> tuple[NeighborSearch, PairList | None]:
    """The pair search of a vertex, answered from the path's pair list (`LISTED_GAP`), which
    is made again at the vertex once its particles have moved too far for the queries of a
    pivot (relative gaps up to `LISTED_QUERY_GAP`). In a box too small for the list's cutoff
    the tree answers every query."""
    largest = float(refinement.diameters.max())
    search = NeighborSearch(refinement.positions, refinement.diameters, box,
                            pair_list=pair_list)
    cutoff = largest * (1.0 + LISTED_GAP)
    if not cutoff < search.half_period:
        return search, None
    if pair_list is None or search.listed_reach() < largest * (1.0 + LISTED_QUERY_GAP):
        pair_list = search.pair_list(cutoff)
        search = NeighborSearch(refinement.positions, refinement.diameters, box,
                                pair_list=pair_list)
    return search, pair_list


def _jacobian_at(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                 i: np.ndarray, j: np.ndarray, stable: np.ndarray) -> sp.csr_matrix:
    """The contact Jacobian of network (i, j) at a configuration (`calippso.certification.newton`)."""
    vectors = minimum_image(positions[i] - positions[j], box)
    return network_jacobian(vectors, 0.5 * (diameters[i] + diameters[j]), i, j, stable)


def _floppy_mode(search: NeighborSearch, i: np.ndarray, j: np.ndarray, stable: np.ndarray,
                 gamma_row: int, basis: Basis | None, swapped: tuple[int, ...],
                 released_in_place: bool) -> tuple[np.ndarray, Basis | None] | None:
    """The floppy mode of a network with one contact fewer than unknowns, per particle.

    The mode t is the null vector of the network's rows other than `gamma_row`, normalised
    to dΓ = 1. When `released_in_place` (row `gamma_row` is the released pair of the vertex,
    and the release keeps the unknowns), t is read from the vertex's own Jacobian J: the solution u of J u = e_c vanishes on every
    other row, so t = u / u_Γ, where u_Γ is minus the released force. J is as well
    conditioned as the network, so factors from an earlier vertex serve it (with the rows
    swapped since, `swapped`, and refinement for the motion). Otherwise (the release left
    rattlers and changed the unknowns; row `gamma_row` is a placeholder) K t = e_Γ is
    solved, with K the Jacobian with Γ's row in place of row `gamma_row`; K is as
    ill-conditioned as the released force is weak, so it is factorised at the vertex
    itself.

    Parameters
    ----------
    basis : Basis or None
        Factors to solve with, where J differs from the basis in rows `swapped`; None, or
        factors that do not reach round-off: a new basis is made.

    Returns
    -------
    (ndarray, shape (N, d), Basis or None) or None
        The displacement of every particle per unit of Γ (zero for the pinned particle and
        the rattlers), and the new basis when one was made (the factors of J, or of K when
        the unknowns changed). None when Γ cannot grow along the floppy mode (K is singular).
    """
    n, d = search.positions.shape
    pairs = search.pairs_of(i, j)
    jacobian = network_jacobian(pairs.vectors, pairs.sigma, i, j, stable)
    n_unknowns = jacobian.shape[1]
    made = None
    if jacobian.shape[0] != n_unknowns:
        return None
    if released_in_place:   # the vertex's own Jacobian
        released = np.zeros(n_unknowns)
        released[gamma_row] = 1.0
        opening = _solve_swapped(basis, jacobian, swapped, released)
        if opening is None:
            made = _basis_of(jacobian, stable)
            opening = _solve_swapped(made, jacobian, (), released)
        if opening is None:
            return None
        growth = opening[-1]
        if not abs(growth) > SINGULAR_GROWTH * np.abs(opening).max():
            return None
        solution = opening / growth
    else:   # K: the network's rows and Γ's
        matrix = sp.vstack([jacobian[:gamma_row],
                            sp.csr_matrix(([1.0], ([0], [n_unknowns - 1])),
                                          shape=(1, n_unknowns)),
                            jacobian[gamma_row + 1:]]).tocsr()
        target = np.zeros(n_unknowns)
        target[gamma_row] = 1.0
        made = _basis_of(matrix, stable, gamma_row)
        solution = _solve_swapped(made, matrix, (), target)
        if solution is None:
            return None
    members = np.flatnonzero(stable)
    mode = np.zeros((n, d))
    mode[members[1:]] = solution[:-1].reshape(-1, d)
    return mode, made


def _basis_of(matrix: sp.csr_matrix, stable: np.ndarray,
              gamma_row: int | None = None) -> Basis | None:
    """A basis of new factors of `matrix`, or None when it is singular."""
    factors = factorize(matrix.tocsc(), strict=False)
    return None if factors is None else Basis(factors, matrix, stable, gamma_row)


def _solve_swapped(basis: Basis | None, matrix: sp.csr_matrix, rows: tuple[int, ...],
                   rhs: np.ndarray) -> np.ndarray | None:
    """matrix⁻¹ rhs from a basis that differs from it in `rows` (and by motion elsewhere),
    refined to a normwise backward error of round-off against it (the floppy mode is a
    direction: Newton's corrector makes the vertex it leads to exact); None when there is
    no basis or it does not serve."""
    factors = None if basis is None else basis.factors_for(matrix, rows)
    return None if factors is None else refined_solve(matrix, factors, rhs, normwise=True)


def _leaving_contacts(vertex: Vertex, bland: bool) -> np.ndarray:
    """The contacts to release, in the order to try them: the non-positive forces, most
    negative first; on a degenerate stretch of the path only the one of smallest pair key
    (Bland's rule)."""
    forces = vertex.refinement.forces
    candidates = np.flatnonzero(forces <= MIN_FORCE_RATIO * float(forces.max()))
    if bland:
        return candidates[[np.argmin(vertex.keys[candidates])]]
    return candidates[np.argsort(forces[candidates], kind="stable")]


def _network_digest(vertex: Vertex) -> bytes:
    return np.sort(vertex.keys).tobytes()


def _from_start(refined: Refinement, positions: np.ndarray, diameters: np.ndarray,
                box: np.ndarray, stable: np.ndarray) -> Refinement:
    """`refined` with its growth and largest displacement measured from the path's start."""
    moved = minimum_image(refined.positions[stable] - positions[stable], box)
    return Refinement(
        positions=refined.positions, diameters=refined.diameters, forces=refined.forces,
        iterations=refined.iterations, factorizations=refined.factorizations,
        sqrt_gamma_minus_1=float(np.mean(refined.diameters / diameters)) - 1.0,
        max_displacement=float(np.abs(moved).max(initial=0.0)), residual=refined.residual)
