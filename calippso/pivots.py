"""Contact pivots: an active-set path from a network that is a few contacts off to the jammed one.

The start is an isostatic contact network C at its Newton point (`calippso.newton`): the
contact equations |r_c|² = Γ σ_c² hold on C, no other pair of stable particles overlaps,
and the forces y (the self-stress of Jᵀ y = (0, …, 0, −1)) are known, but some are not
positive. The CALiPPSO LP at that point would move on; here the same move is made on the
exact geometry, one contact at a time, as the simplex method moves from vertex to vertex:

1. **Certify.** Every force positive: the point is the jamming point (the caller still runs
   the certificate of `calippso.network.certify_network`).
2. **Release** a contact c with y_c ≤ 0 (the most negative one, or the next ones when its
   release gives no pivot; smallest pair key while the path is degenerate, Bland's rule, so
   that it cannot cycle). The network A = C ∖ c, less
   the particles it leaves with only d contacts (rattlers, removed recursively with their
   contacts), has exactly one floppy mode t: J_A t = 0, normalised to dΓ = 1. Along it c
   opens, because y_cᵀ (J_C t)_c = −dΓ, and Γ grows.
3. **Ratio test.** Every pair q of stable particles outside A closes along t at the
   inflation step δ_q = Φ_q / (−∇Φ_q · t), where Φ_q = |r_q|²/σ_q² − Γ. The pair with the
   smallest step closes first; among pairs within round-off of it, the one that closes
   fastest (Harris's ratio test, for a well-conditioned network).
4. **Pivot in.** C' = A ∪ {k} is isostatic again. Newton solves it from the predicted point
   x + δ_k t, which makes the linear ratio test exact: the new vertex is accepted when no
   other pair overlaps there and Γ did not decrease; otherwise the next pair of the ratio
   test is tried. Its forces cost one transposed solve. Repeat from 1.

Rattlers (those of the start, and those a release leaves) carry no force and do not move
with the floppy modes; when a moved cage overlaps its rattler, the rattler is moved out of
the way (`calippso.rattlers.separate_rattlers`). When a cage closes on its rattler before
the pair of the ratio test closes, the rattler joins the network with the d + 1 pairs of its
cage (d unknowns and d + 1 rows: the released network becomes isostatic again). When the
cage of a particle that the release left with d contacts closes on it, the pivot is made
again with that particle kept in the network, held by its d contacts.

A start that Newton cannot solve because its Jacobian is singular (isostatic by count but
not by rank: a floppy cluster somewhere, balanced by a redundant contact elsewhere) is
repaired first (`_repair_singular`): one sparse LU of the bordered Jacobian gives its floppy
mode t and its self-stress s (`singular_vectors`); a contact that s marks as redundant opens
(the sign of s chosen so that it opens, not overlaps), the network closes without it, and t
is followed with Γ not decreasing until the ratio test closes a pair. That swap is the
path's first (`Swap.repaired`), and the ordinary pivots go on from its vertex. A vertex
whose every release leaves a singular network (Newton solved a singular network on factors
with perturbed pivots, and its forces are not unique) is repaired the same way.

Γ never decreases, so the path can only revisit a network through degenerate pivots (where
the closing pair already touches); Bland's rule and a record of the networks seen since Γ
last grew rule that out.

One sparse LU (`calippso.sparse_lu`) serves many pivots: a pivot swaps one row of the
Jacobian, and solves with the swapped matrix use the stored factors and the Woodbury
identity (`_Basis`), refined iteratively against the exact matrix; the Jacobian is
factorised again when 40 rows have been swapped, when the refinement does not reach
round-off, or when rattlers change the unknowns.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.linalg import lu_factor, lu_solve

from .neighbors import NeighborSearch, Pairs
from .network import NEWTON_OVERLAP_TOLERANCE
from .newton import (MAX_CORRECTION, MAX_ITERATIONS, MAX_REFINEMENTS, MIN_FORCE_RATIO,
                     NEWTON_FAILED, REFINEMENT_TOLERANCE, RESIDUAL_TOLERANCE, STEP_TOLERANCE,
                     Refinement, network_jacobian, refine_isostatic)
from .packing import minimum_image, wrap
from .rattlers import remove_rattlers, separate_rattlers
from .sparse_lu import Factors, factorize

__all__ = ["PivotPath", "Swap", "pivot_to_jamming", "describe_path", "singular_vectors",
           "least_norm_solve", "onto_contacts", "MAX_PIVOTS", "NEAR_GAP", "MAX_NEAR_GAP",
           "DEGENERATE_STEP", "CAGE_CLOSED"]

#: Pivots taken at most before the path gives up (a network a few contacts off takes a few
#: to a few tens).
MAX_PIVOTS = 500
#: Pairs of stable particles closer than this relative gap enter the ratio test; a step that
#: could close a pair beyond it reads the pairs `NEAR_GAP_WIDENING` times farther.
NEAR_GAP = 1e-3
NEAR_GAP_WIDENING = 10.0
#: Largest relative gap read by the ratio test: a floppy mode that closes no pair within it
#: is not a small correction of the network.
MAX_NEAR_GAP = 0.3
#: An inflation step (relative, ΔΓ/Γ) below this is a degenerate pivot: the closing pair
#: already touches, Γ does not grow.
DEGENERATE_STEP = 1e-14
#: Largest displacement component of a rattler moved out of the way of its moved cage
#: (mean diameters): the cages move by up to ~1e-4 over a path.
RATTLER_REACH = 1e-3
#: A caged rattler's d + 1 closest neighbours are looked for within this relative gap.
CAGE_GAP = 1e-2
#: Caged rattlers tried (the deepest overlaps first) when one must rejoin the network: each
#: try is a Newton solve with new unknowns.
REJOIN_TRIES = 2
#: Why a pivot failed when a rattler's cage closed on it (the pivot is then tried again with
#: the particles that the release leaves with d contacts kept in the network).
CAGE_CLOSED = "a rattler's cage closed along the floppy mode"
#: Rows swapped into one factorisation (`_Basis`) before the Jacobian is factorised again.
MAX_ROW_SWAPS = 40
#: The k × k system of the Woodbury identity is refused beyond this condition number (its
#: solves would lose the accuracy that the chord steps and refinement need).
MAX_SMALL_CONDITION = 1e10
#: Swaps listed by name in `describe_path`.
LISTED_SWAPS = 5
#: Harris's ratio test treats pairs within this much of Φ = |r|²/σ² − Γ (about twice the
#: relative gap) as closing together: well inside the overlap tolerance of the certificate.
HARRIS_SLACK = 1e-12
#: Pairs of the ratio test tried in turn, when Newton's vertex for the first one overlaps
#: another pair (the curve is not the line of the prediction).
RATIO_CANDIDATES = 4
#: Why a pivot failed when the network without the released contact is singular (Γ cannot
#: grow along its floppy modes); when every release fails so, the vertex's own network is
#: singular and is repaired (`_repair_singular`).
SINGULAR_RELEASE = "the network without the released contact is singular"
#: Contacts with non-positive forces tried in turn (most negative first) when releasing one
#: gives no pivot: its released network is singular (a floppy cluster held by a redundant
#: contact), or its floppy mode closes no pair. Any of them may leave: Γ grows along each.
LEAVING_TRIES = 5

#: Seed of the random border of the rank-revealing system (`singular_vectors`): fixed, so
#: that a repair is reproducible.
BORDER_SEED = 34
#: A network's Jacobian is singular (and its start is repaired, `_repair_singular`) when
#: the null vector t of the bordered system leaves |J t| below this fraction of |J| |t|
#: (largest row). A floppy cluster leaves round-off; a regular contact Jacobian leaves far
#: more (its smallest singular value is ~1e-4 of its largest in a jammed packing of 64
#: spheres). Components of the null vector (largest 1) below it are round-off: the mode
#: does not move those coordinates (nor Γ, for a floppy cluster).
SINGULAR_RESIDUAL = 1e-8
#: The sign rule of a repair is undecided when sᵀΦ (or its curvature along the floppy mode)
#: is below this fraction of the same sum with |s| and |Φ|: round-off, the redundant contacts
#: do not move along the mode (its floppy cluster is apart from them), and either may open.
UNDECIDED_SIGN = 1e-8
#: Contacts whose self-stress is below this fraction of the largest are not opened by a
#: repair: without them the network would stay nearly singular.
REDUNDANT_RATIO = 1e-3
#: Redundant contacts tried in turn by a repair (`_repair_singular`), each with the first
#: pairs of the ratio test; each try is a Newton solve.
REPAIR_TRIES = 3


@dataclass(frozen=True)
class Swap:
    """One pivot: the contact released, the pair closed, and the inflation gained.

    Attributes
    ----------
    released : tuple of int
        The contact (i, j) whose force was not positive.
    closed : tuple of int
        The pair (i, j) that closed along the floppy mode.
    growth : float
        √(Γ'/Γ) − 1: the relative diameter growth of this pivot (0 when degenerate).
    new_rattlers : int
        Particles the release left with d contacts (they leave the network).
    rejoined : int
        Rattlers whose cage closed along the floppy mode (they join the network with d + 1
        contacts; `closed` is the first of them).
    repaired : bool
        The swap repaired a singular network (`_repair_singular`: the start, or a vertex
        that Newton solved on factors with perturbed pivots): `released` is the
        redundant contact opened, `closed` the pair that closed the floppy mode, and
        `growth` is measured from where the network without the released contact closes.
    """

    released: tuple[int, int]
    closed: tuple[int, int]
    growth: float
    new_rattlers: int
    rejoined: int = 0
    repaired: bool = False


@dataclass(frozen=True, eq=False)
class PivotPath:
    """The end of a pivot path: an isostatic network at its Newton point, with positive forces
    (`jammed`), or the last vertex that the path reached before it had to stop.

    Attributes
    ----------
    i, j : ndarray, shape (M,), int64
        Contacts between stable particles, i < j.
    rattlers : ndarray, shape (N,), bool
    refinement : Refinement
        The jamming point (positions, diameters, forces), with its growth and largest
        displacement measured from the start of the path.
    swaps : tuple of Swap
        The pivots in order (with the repairs of singular networks, `Swap.repaired`).
    factorizations : int
        Sparse LU factorisations (directions and Newton solves).
    seconds : float
        Wall time of the path.
    jammed : bool
        Every force is positive: the path reached a jamming point. False: the path stopped
        (why is returned beside it) at this vertex, no lower in Γ than its start.
    closed : tuple of (int, int)
        The pairs that closed the floppy modes of a hypostatic start before the first pivot
        (`calippso.floppy_modes`), in order; empty when the start was isostatic.
    """

    i: np.ndarray
    j: np.ndarray
    rattlers: np.ndarray
    refinement: Refinement
    swaps: tuple[Swap, ...]
    factorizations: int
    seconds: float
    jammed: bool = True
    closed: tuple[tuple[int, int], ...] = ()

    @property
    def pivots(self) -> int:
        """Pivots taken."""
        return len(self.swaps)

    @property
    def degenerate(self) -> int:
        """Pivots that gained no inflation."""
        return sum(swap.growth <= DEGENERATE_STEP for swap in self.swaps)

    @property
    def repairs(self) -> int:
        """Swaps that repaired a singular network (`Swap.repaired`)."""
        return sum(swap.repaired for swap in self.swaps)

    @property
    def largest_growth(self) -> float:
        """The largest relative diameter growth of one pivot."""
        return max((swap.growth for swap in self.swaps), default=0.0)


@dataclass(frozen=True, eq=False)
class _Vertex:
    """A point of the path: an isostatic network at its Newton point (diameters σ √Γ, so that
    Φ_c = |r_c|²/σ_c² − 1 vanishes on the contacts)."""

    i: np.ndarray
    j: np.ndarray
    stable: np.ndarray
    refinement: Refinement
    basis: _Basis | None = None
    swapped: tuple[int, ...] = ()

    @property
    def keys(self) -> np.ndarray:
        return self.i * self.stable.shape[0] + self.j


class _SwappedFactors:
    """Solves with a matrix M that equals a factorised base matrix B but in k rows R, by the
    Woodbury identity: with W = B⁻¹ E_R (n × k) and V = M[R] − B[R] (k × n), S = I + V W,

        M⁻¹ b = y − W S⁻¹ V y  (y = B⁻¹ b),   M⁻ᵀ b = B⁻ᵀ (b − Vᵀ S⁻ᵀ Wᵀ b):

    one solve with the base factors and a k × k system per solve."""

    def __init__(self, base: Factors, columns: np.ndarray, changes: sp.csr_matrix,
                 small: tuple[np.ndarray, np.ndarray]):
        self._base, self._columns, self._changes, self._small = base, columns, changes, small

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        if trans == "T":
            weights = lu_solve(self._small, self._columns.T @ rhs, trans=1)
            return self._base.solve(rhs - self._changes.T @ weights, trans="T")
        solution = self._base.solve(rhs)
        return solution - self._columns @ lu_solve(self._small, self._changes @ solution)


class _Basis:
    """One sparse LU of a network's Jacobian (unknowns of the stable set `stable`), reused by
    the pivots that follow: a pivot swaps one row, and `factors_for` solves with the swapped
    matrix by the Woodbury identity (`_SwappedFactors`). The columns B⁻¹ e_r are kept."""

    def __init__(self, factors: Factors, matrix: sp.spmatrix, stable: np.ndarray):
        self.factors = factors
        self.matrix = sp.csr_matrix(matrix)
        self.stable = stable
        self._columns: dict[int, np.ndarray] = {}

    def fits(self, stable: np.ndarray) -> bool:
        """Whether the unknowns are those of the basis (same stable particles)."""
        return bool(np.array_equal(self.stable, stable))

    def factors_for(self, matrix: sp.spmatrix, rows: tuple[int, ...]) -> Factors | None:
        """Factors of `matrix`, which differs from the basis in `rows` (and by the motion of
        the particles elsewhere: the factors are then those of a nearby matrix); None when
        there are more than `MAX_ROW_SWAPS` rows or the small system is singular."""
        if not rows:
            return self.factors
        if len(rows) > MAX_ROW_SWAPS:
            return None
        index = np.array(rows)
        for row in rows:
            if row not in self._columns:
                unit = np.zeros(self.matrix.shape[0])
                unit[row] = 1.0
                self._columns[row] = self.factors.solve(unit)
        columns = np.column_stack([self._columns[row] for row in rows])
        changes = sp.csr_matrix(matrix)[index] - self.matrix[index]
        small = np.eye(index.size) + changes @ columns
        if not np.all(np.isfinite(small)) or np.linalg.cond(small) > MAX_SMALL_CONDITION:
            return None
        return _SwappedFactors(self.factors, columns, sp.csr_matrix(changes), lu_factor(small))


def pivot_to_jamming(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                     i: np.ndarray, j: np.ndarray, rattlers: np.ndarray,
                     refined: Refinement | None = None,
                     max_pivots: int = MAX_PIVOTS) -> tuple[PivotPath | None, str]:
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
        Newton's solution of the network from `positions`, when already computed. Without
        it Newton solves the network; when it cannot (a singular Jacobian), the network is
        repaired (`_repair_singular`), and that repair is the path's first pivot. A vertex
        whose every release leaves a singular network is repaired the same way.
    max_pivots : int
        Pivots taken at most (a repair counts as one).

    Returns
    -------
    (PivotPath or None, str)
        The path's end, with positive forces and no overlap (`PivotPath.jammed`), and "";
        or where it stopped and why: the network became singular, a floppy mode closes no
        pair near contact, a rattler's cage closed, or `max_pivots` were taken (a
        `PivotPath` with ``jammed=False`` once a pivot was made, None when the start itself
        is refused: another pair overlaps there, or Newton fails and the network is not
        singular or its repair fails).
    """
    began = time.perf_counter()
    i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
    stable = ~np.asarray(rattlers, dtype=bool)
    start_positions, start_diameters = positions, diameters
    swaps: list[Swap] = []
    if refined is None:
        refined = refine_isostatic(positions, diameters, box, i, j, stable)
    if refined is None:   # a singular network has no Newton point: repair it
        repaired, failure = _repair_singular(positions, diameters, box, i, j, stable)
        if repaired is None:
            return None, f"{NEWTON_FAILED}; no repair: {failure}"
        vertex, swap, factorizations = repaired
        swaps.append(swap)
    else:
        refined = _rattlers_out_of_the_way(
            NeighborSearch(refined.positions, refined.diameters, box), refined, stable)
        if refined is None:
            return None, "a rattler overlaps its cage at the start"
        basis = (None if refined.factorization is None
                 else _Basis(*refined.factorization, stable))
        vertex = _Vertex(i, j, stable, refined, basis)
        factorizations = refined.factorizations
    seen = {_network_digest(vertex)}
    degenerate = bool(swaps) and swaps[0].growth <= DEGENERATE_STEP

    def ended(jammed: bool) -> PivotPath:
        return PivotPath(vertex.i, vertex.j, ~vertex.stable,
                         _from_start(vertex.refinement, start_positions, start_diameters, box,
                                     vertex.stable),
                         tuple(swaps), factorizations, time.perf_counter() - began, jammed)

    while True:
        search = NeighborSearch(vertex.refinement.positions, vertex.refinement.diameters, box)
        overlapping = int(np.sum(outside_pairs(search, vertex.keys, vertex.stable, NEAR_GAP).gaps
                                 < -NEWTON_OVERLAP_TOLERANCE))
        if overlapping:
            return None, f"{overlapping} other pair(s) overlap"
        if vertex.refinement.positive:
            return ended(True), ""
        if len(swaps) >= max_pivots:
            return ended(False), f"no jamming point within {max_pivots} pivots"
        failures = set()
        for released in _leaving_contacts(vertex, bland=degenerate)[:LEAVING_TRIES]:
            step, failure = _pivot(search, vertex, int(released))
            if step is None and failure == CAGE_CLOSED:
                # the particles the release left with d contacts stay in the network
                step, failure = _pivot(search, vertex, int(released), attached=True)
            if step is not None:
                break
            failures.add(failure)
        if step is None and failures == {SINGULAR_RELEASE}:
            # every release leaves a singular network: the vertex's own is singular (Newton
            # ran on factors with perturbed pivots, and its forces are not unique)
            refinement = vertex.refinement
            step, why = _repair_singular(refinement.positions, refinement.diameters, box,
                                         vertex.i, vertex.j, vertex.stable)
            failure = failure if step is not None else f"{failure}; no repair: {why}"
        if step is None:
            return (ended(False) if swaps else None), failure
        next_vertex, swap, solves = step
        factorizations += solves
        degenerate = swap.growth <= DEGENERATE_STEP
        if not degenerate:   # Γ grew: no network seen so far can come back
            seen.clear()
        digest = _network_digest(next_vertex)
        if digest in seen:
            return ended(False), "the path returned to a network it had left (cycling)"
        seen.add(digest)
        swaps.append(swap)
        vertex = next_vertex


def _pivot(search: NeighborSearch, vertex: _Vertex, released: int,
           attached: bool = False) -> tuple[tuple[_Vertex, Swap, int] | None, str]:
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
    ((next vertex, swap, factorisations) or None, str)
    """
    n, d = vertex.refinement.positions.shape
    keep = np.ones(vertex.i.shape[0], dtype=bool)
    keep[released] = False
    if attached:
        i_a, j_a, stable = vertex.i[keep], vertex.j[keep], vertex.stable
    else:
        ratt, kept = remove_rattlers(n, d, vertex.i[keep], vertex.j[keep])
        i_a, j_a, stable = vertex.i[keep][kept], vertex.j[keep][kept], ~ratt
    if np.array_equal(stable, vertex.stable):
        # same unknowns: the row of the released contact is swapped in place
        rows_i, rows_j, swap_row = vertex.i, vertex.j, released
        basis, swapped = vertex.basis, vertex.swapped
    else:   # rattlers left with their contacts: new unknowns, the swapped row last
        rows_i, rows_j, swap_row = np.append(i_a, 0), np.append(j_a, 0), i_a.shape[0]
        basis, swapped = None, ()
    if basis is not None and not basis.fits(stable):
        basis, swapped = None, ()
    mode = _floppy_mode(search, rows_i, rows_j, stable, swap_row, basis, swapped)
    if mode is None:
        return None, SINGULAR_RELEASE
    direction, made = mode
    solves = 0
    if made is not None:   # K was factorised: the basis of this pivot and the next ones
        basis, swapped, solves = _Basis(*made, stable), (), 1
    c_i, c_j = int(vertex.i[released]), int(vertex.j[released])
    if stable[c_i] and stable[c_j]:
        c_pair = search.pairs_of(np.array([c_i]), np.array([c_j]))
        if _closing_rates(c_pair, direction)[0] <= 0:
            return None, "the released contact does not open along its floppy mode"
    ratio_test = find_closing_pairs(search, i_a * n + j_a, stable, direction)
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
        if refined is None:
            continue
        solves += refined.factorizations
        growth = float(np.mean(refined.diameters / diameters)) - 1.0
        if growth < -DEGENERATE_STEP:
            continue
        now_rattlers, kept = remove_rattlers(n, d, i_new, j_new)
        if attached and not kept.all():   # left with d contacts: zero forces, rattlers now
            i_new, j_new = i_new[kept], j_new[kept]
            refined = replace(refined, forces=refined.forces[kept])
        now_stable = ~now_rattlers
        moved = NeighborSearch(refined.positions, refined.diameters, search.box)
        if np.any(outside_pairs(moved, i_new * n + j_new, now_stable,
                                NEAR_GAP).gaps < -NEWTON_OVERLAP_TOLERANCE):
            continue
        separated = _rattlers_out_of_the_way(moved, refined, now_stable)
        if separated is None:   # a cage closed on its rattler before this pair closed
            rejoined = _rejoin_caged(moved, vertex, i_a, j_a, stable, (c_i, c_j))
            if rejoined is not None:
                joined, pairs, joined_growth = rejoined
                solves += joined.refinement.factorizations
                swap = Swap((c_i, c_j), pairs[0], max(joined_growth, 0.0),
                            int(np.count_nonzero(~stable & vertex.stable)), rejoined=1)
                return (joined, swap, solves), ""
            return None, CAGE_CLOSED   # a later pair of the ratio test would close it too
        refined = separated
        if refined.factorization is not None:
            next_basis, next_swaps = _Basis(*refined.factorization, stable), ()
        else:
            next_basis, next_swaps = basis, next_swapped
        if not np.array_equal(now_stable, stable):   # the rows of the new rattlers left
            next_basis, next_swaps = None, ()
        candidate = _Vertex(i_new, j_new, now_stable, refined, next_basis, next_swaps)
        swap = Swap((c_i, c_j), (int(near.i[closing]), int(near.j[closing])), max(growth, 0.0),
                    int(np.count_nonzero(now_rattlers & vertex.stable)))
        return (candidate, swap, solves), ""
    return None, "Newton found no vertex without overlap along the floppy mode"


def _jacobian_at(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                 i: np.ndarray, j: np.ndarray, stable: np.ndarray) -> sp.csr_matrix:
    """The contact Jacobian of network (i, j) at a configuration (`calippso.newton`)."""
    vectors = minimum_image(positions[i] - positions[j], box)
    return network_jacobian(vectors, 0.5 * (diameters[i] + diameters[j]), i, j, stable)


def _rejoin_caged(moved: NeighborSearch, vertex: _Vertex, i_a: np.ndarray, j_a: np.ndarray,
                  stable: np.ndarray, released: tuple[int, int]
                  ) -> tuple[_Vertex, list[tuple[int, int]], float] | None:
    """A rattler whose cage closed along the floppy mode joins the network again.

    `moved` is the configuration one pair too far along the mode, where a rattler overlaps
    its cage and cannot be moved out. Its d + 1 closest pairs with stable particles there
    (its cage, never the `released` contact) close instead: the released network A (one
    floppy mode) with those d + 1 rows and the rattler's d unknowns is isostatic, and Newton
    solves it from the vertex.

    Returns
    -------
    (vertex, pairs, growth) or None
        The new vertex, the cage's pairs, the relative diameter growth; None when neither of
        the `REJOIN_TRIES` rattlers that overlap most gives a vertex with no overlap.
    """
    n, d = moved.positions.shape
    close = moved.pairs_within(float(moved.diameters.max()) * (1.0 + CAGE_GAP))
    one_rattler = (stable[close.i] != stable[close.j]) & ~(
        (close.i == released[0]) & (close.j == released[1]))
    overlapping = one_rattler & (close.gaps < -NEWTON_OVERLAP_TOLERANCE)
    rattler_of = np.where(stable[close.i], close.j, close.i)
    caged = np.unique(rattler_of[overlapping])
    positions, diameters = vertex.refinement.positions, vertex.refinement.diameters
    deepest = np.argsort([close.gaps[overlapping & (rattler_of == r)].min() for r in caged])
    for rattler in caged[deepest][:REJOIN_TRIES]:
        own = np.flatnonzero(one_rattler & (rattler_of == rattler))
        if own.size < d + 1:
            continue
        cage = own[np.argsort(close.gaps[own])[:d + 1]]
        i_new = np.concatenate([i_a, close.i[cage]])
        j_new = np.concatenate([j_a, close.j[cage]])
        joined = stable.copy()
        joined[rattler] = True
        refined = refine_isostatic(positions, diameters, moved.box, i_new, j_new, joined)
        if refined is None:
            continue
        growth = float(np.mean(refined.diameters / diameters)) - 1.0
        after = NeighborSearch(refined.positions, refined.diameters, moved.box)
        candidate = _Vertex(i_new, j_new, joined, refined)
        overlaps = outside_pairs(after, candidate.keys, joined, NEAR_GAP).gaps
        if growth < -DEGENERATE_STEP or np.any(overlaps < -NEWTON_OVERLAP_TOLERANCE):
            continue
        separated = _rattlers_out_of_the_way(after, refined, joined)
        if separated is None:
            continue
        pairs = [(int(a), int(b)) for a, b in zip(close.i[cage], close.j[cage])]
        return _Vertex(i_new, j_new, joined, separated), pairs, growth
    return None


class _TransposedFactors:
    """The factors of Aᵀ, from factors of A (for `refined_solve` with a transposed matrix)."""

    def __init__(self, factors: Factors):
        self._factors = factors

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        return self._factors.solve(rhs, trans="N" if trans == "T" else "T")


def singular_vectors(jacobian: sp.spmatrix) -> tuple[np.ndarray, np.ndarray] | None:
    """The null vector t (J t = 0) and the self-stress s (Jᵀ s = 0) of a square Jacobian of
    rank one less than its size, from one sparse LU of the bordered matrix

        B = [ J   b ]      B [t; τ] = [0; 1],   Bᵀ [s; ς] = [0; 1],
            [ cᵀ  0 ],

    with random borders b, c (`BORDER_SEED`, scaled to the entries of J): B is non-singular
    when b is outside the range of J and c is not orthogonal to its null vector, and then
    τ = ς = 0 and t, s span the two null spaces (Keller's bordering). For a non-singular J
    the same solves give vectors with J t = −τ b ≠ 0: the caller judges the residual.

    Parameters
    ----------
    jacobian : sparse matrix, shape (M, M)
        The contact Jacobian of a network (`calippso.newton.network_jacobian`), its last
        column Γ's.

    Returns
    -------
    (ndarray, ndarray) or None
        t and s, shape (M,) each, scaled to a largest component of 1 (t: positions per unit
        of the mode, its last component dΓ; s: one weight per contact); None when B is
        singular too (J lacks more than one rank) or its solves do not refine to round-off.
    """
    m = jacobian.shape[0]
    matrix = sp.csr_matrix(jacobian)
    scale = float(np.abs(matrix.data).mean()) if matrix.nnz else 1.0
    column, row = scale * np.random.default_rng(BORDER_SEED).standard_normal((2, m))
    bordered = sp.bmat([[matrix, sp.csr_matrix(column[:, None])],
                        [sp.csr_matrix(row[None, :]), None]], format="csc")
    factors = factorize(bordered, strict=False)
    if factors is None:
        return None
    unit = np.zeros(m + 1)
    unit[m] = 1.0
    null = refined_solve(bordered.tocsr(), factors, unit, normwise=True)
    stress = refined_solve(bordered.T.tocsr(), _TransposedFactors(factors), unit,
                           normwise=True)
    if null is None or stress is None:
        return None
    null, stress = null[:m], stress[:m]
    return null / np.abs(null).max(), stress / np.abs(stress).max()


def _repair_singular(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                     i: np.ndarray, j: np.ndarray, stable: np.ndarray
                     ) -> tuple[tuple[_Vertex, Swap, int] | None, str]:
    """Repair an isostatic network whose Jacobian is singular: open a redundant contact,
    close the floppy mode.

    With J singular (rank M − 1) the network holds a floppy mode t (J t = 0: a floppy
    cluster, or Γ growing with every contact closed) and a self-stress s (Jᵀ s = 0, so
    Σ s = 0: a redundant subnetwork), `singular_vectors`. Releasing a contact c with
    s_c ≠ 0 leaves A = C ∖ c, M − 1 independent rows whose one-dimensional null space is t
    still. The combination sᵀΦ of the contact equations Φ_k = |r_k|²/σ_k² − Γ does not
    change to first order along any motion (sᵀJ = 0), so wherever A's contacts close,
    s_c Φ_c = sᵀΦ: from the start Φ⁰ to first order, and along t by λ²/2 Σ_k s_k
    2|Δt_k|²/σ_k² more at a step λ (Δt_k the relative displacement of contact k). The sign
    rule: s is oriented so that sᵀΦ⁰ > 0, or, at a start whose contacts all close (to
    `RESIDUAL_TOLERANCE`), so that the second-order term is positive; c is a contact with
    s_c ≥ `REDUNDANT_RATIO` (those whose particles keep d + 1 contacts first, then the
    largest s_c: the best-conditioned release), and c then opens. When both terms vanish
    (`UNDECIDED_SIGN`: the floppy cluster is apart from the redundant contacts, which the
    mode does not move), c is chosen by |s_c| in the same order, and it stays at contact.

    A's contacts close by least-norm steps in positions and Γ (`onto_contacts`); from there
    t is followed with Γ not decreasing (t_Γ ≥ 0; a floppy cluster has t_Γ = 0, Γ moves at
    second order only, and it is followed both ways) and the ratio test
    (`find_closing_pairs`, c left out) gives the pair k that closes first. Newton solves
    A ∪ {k} from the predicted point, which is accepted when Γ did not decrease from where
    A's contacts closed, no other pair (c included) overlaps, and the rattlers clear their
    cages; particles that A ∪ {k} leaves with d contacts (their forces vanish) become
    rattlers with their contacts. Otherwise the next pair of the ratio test, then the next
    redundant contact, is tried.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (mean diameters), with the network's pairs near contact.
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    i, j : ndarray, shape (M,), int64
        The network, M = d (N_s − 1) + 1, i < j.
    stable : ndarray, shape (N,), bool

    Returns
    -------
    ((vertex, swap, factorisations) or None, str)
        The first vertex of the path and its swap (`Swap.repaired`, its growth measured
        from where A's contacts closed), with the sparse LUs of the bordered system and of
        Newton (the least-norm steps' are not counted); or None and why.
    """
    n, d = positions.shape
    vectors = minimum_image(positions[i] - positions[j], box)
    ratios = np.einsum("md,md->m", vectors, vectors) / (0.5 * (diameters[i] + diameters[j]))**2
    scaled = diameters * np.sqrt(float(np.mean(ratios)))   # Γ = 1 at the contacts' mean
    sigma = 0.5 * (scaled[i] + scaled[j])
    jacobian = network_jacobian(vectors, sigma, i, j, stable)
    if jacobian.shape[0] != jacobian.shape[1]:
        return None, "the network is not isostatic"
    found = singular_vectors(jacobian)
    if found is None:
        return None, "the Jacobian lacks more than one rank"
    null, stress = found
    if float(np.abs(jacobian @ null).max()) > SINGULAR_RESIDUAL * float(
            (abs(jacobian) @ np.abs(null)).max()):
        return None, "the Jacobian is not singular"
    if null[-1] < 0:   # Γ does not decrease along the mode
        null = -null
    null[np.abs(null) <= SINGULAR_RESIDUAL] = 0.0   # round-off: what the mode does not move
    # a floppy cluster leaves Γ flat to first order and may move either way
    senses = (1.0, -1.0) if null[-1] == 0.0 else (1.0,)
    mode = np.zeros((n, d))
    mode[np.flatnonzero(stable)[1:]] = null[:-1].reshape(-1, d)
    phi = np.einsum("md,md->m", vectors, vectors) / sigma**2 - 1.0
    relative = mode[i] - mode[j]
    curvature = 2.0 * np.einsum("md,md->m", relative, relative) / sigma**2
    # sᵀΦ moves c: at first order from the start, at second order along t from a closed start
    moving = curvature if float(np.abs(phi).max()) <= RESIDUAL_TOLERANCE else phi
    measure = float(stress @ moving)
    if abs(measure) > UNDECIDED_SIGN * float(np.abs(stress) @ np.abs(moving)):
        oriented = stress * np.sign(measure)
    else:   # the mode does not move the redundant contacts (a separate floppy cluster)
        oriented = np.abs(stress)
    opening = np.flatnonzero(oriented >= REDUNDANT_RATIO)
    # releases that leave both particles with d + 1 contacts or more (no new rattler) first
    counts = np.bincount(np.concatenate([i, j]), minlength=n)
    keeps_both = (counts[i[opening]] > d + 1) & (counts[j[opening]] > d + 1)
    solves = 1   # the bordered system
    for released in opening[np.lexsort((-oriented[opening], ~keeps_both))][:REPAIR_TRIES]:
        keep = np.ones(i.shape[0], dtype=bool)
        keep[released] = False
        closing_at = onto_contacts(positions, scaled, box, i[keep], j[keep], stable)
        if closing_at is None:
            continue
        start = NeighborSearch(closing_at[0], scaled * np.sqrt(closing_at[1]), box)
        for sign in senses:
            ratio_test = find_closing_pairs(start, i * n + j, stable, sign * mode,
                                            gamma_rate=sign * null[-1])
            if ratio_test is None:
                continue
            near, steps, candidates = ratio_test
            for closing in candidates[:RATIO_CANDIDATES]:
                predicted = start.positions + sign * float(steps[closing]) * mode
                repaired, made = _repaired_vertex(start, i, j, stable, int(released), near,
                                                  closing, predicted)
                solves += made
                if repaired is not None:
                    return (*repaired, solves), ""
    return None, "no redundant contact and closing pair gave a vertex"


def _repaired_vertex(start: NeighborSearch, i: np.ndarray, j: np.ndarray, stable: np.ndarray,
                     released: int, near: Pairs, closing: int, predicted: np.ndarray
                     ) -> tuple[tuple[_Vertex, Swap] | None, int]:
    """The vertex of a repair (`_repair_singular`): Newton on the network with contact
    `released` swapped for pair `closing` of `near`, from `predicted`.

    Returns
    -------
    ((vertex, swap) or None, int)
        None when Newton fails, Γ decreased from `start`, another pair overlaps, or a cage
        closed on its rattler; and Newton's factorisations (one when it failed).
    """
    n, d = start.positions.shape
    i_new, j_new = i.copy(), j.copy()
    i_new[released], j_new[released] = near.i[closing], near.j[closing]
    refined = refine_isostatic(predicted, start.diameters, start.box, i_new, j_new, stable)
    if refined is None:
        return None, 1
    growth = float(np.mean(refined.diameters / start.diameters)) - 1.0
    if growth < -DEGENERATE_STEP:
        return None, refined.factorizations
    now_rattlers, kept = remove_rattlers(n, d, i_new, j_new)
    i_new, j_new, now_stable = i_new[kept], j_new[kept], ~now_rattlers
    refined = replace(refined, forces=refined.forces[kept])
    moved = NeighborSearch(refined.positions, refined.diameters, start.box)
    if np.any(outside_pairs(moved, i_new * n + j_new, now_stable, NEAR_GAP).gaps
              < -NEWTON_OVERLAP_TOLERANCE):
        return None, refined.factorizations
    separated = _rattlers_out_of_the_way(moved, refined, now_stable)
    if separated is None:
        return None, refined.factorizations
    basis = (_Basis(*refined.factorization, stable) if refined.factorization is not None
             and np.array_equal(now_stable, stable) else None)
    swap = Swap((int(i[released]), int(j[released])),
                (int(near.i[closing]), int(near.j[closing])), max(growth, 0.0),
                int(np.count_nonzero(now_rattlers & stable)), repaired=True)
    return (_Vertex(i_new, j_new, now_stable, separated, basis), swap), refined.factorizations


def _rattlers_out_of_the_way(search: NeighborSearch, refined: Refinement,
                             stable: np.ndarray) -> Refinement | None:
    """`refined` (the configuration of `search`) with its rattlers cleared of the moved cages
    (`clear_rattlers`); None when a cage has closed on its rattler."""
    cleared = clear_rattlers(search, stable)
    return None if cleared is None else replace(refined, positions=cleared)


def clear_rattlers(search: NeighborSearch, stable: np.ndarray) -> np.ndarray | None:
    """The positions of `search` with the rattlers (not `stable`) moved out of the cages that
    overlap them (`calippso.rattlers.separate_rattlers`, within `RATTLER_REACH`), shape
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


def _floppy_mode(search: NeighborSearch, i: np.ndarray, j: np.ndarray, stable: np.ndarray,
                 gamma_row: int, basis: _Basis | None,
                 swapped: tuple[int, ...]
                 ) -> tuple[np.ndarray, tuple[Factors, sp.csr_matrix] | None] | None:
    """The floppy mode of a network with one contact fewer than unknowns, per particle.

    Solves K t = e_Γ, where K is the Jacobian of the pairs (i, j) with the row `gamma_row`
    replaced by the row of Γ (appended when `gamma_row` is the number of pairs): t is the
    null vector of the other rows with dΓ = 1.

    Parameters
    ----------
    basis : _Basis or None
        Factors to solve with, where K differs from the basis in rows `swapped` and
        `gamma_row`; None: K is factorised.

    Returns
    -------
    (ndarray, shape (N, d), (Factors, matrix) or None) or None
        The displacement of every particle per unit of Γ (zero for the pinned particle and
        the rattlers), and K with its new factors when the basis could not serve; None when
        K is singular (Γ cannot grow along the floppy modes).
    """
    n, d = search.positions.shape
    pairs = search.pairs_of(i, j)
    jacobian = network_jacobian(pairs.vectors, pairs.sigma, i, j, stable)
    n_unknowns = jacobian.shape[1]
    rows = [jacobian[:gamma_row],
            sp.csr_matrix(([1.0], ([0], [n_unknowns - 1])), shape=(1, n_unknowns)),
            jacobian[gamma_row + 1:]]
    matrix = sp.vstack(rows).tocsr()
    if matrix.shape[0] != n_unknowns:
        return None
    target = np.zeros(n_unknowns)
    target[gamma_row] = 1.0
    factors = None if basis is None else basis.factors_for(matrix, tuple(sorted(
        set(swapped) | {gamma_row})))
    solution = None if factors is None else refined_solve(matrix, factors, target)
    made = None
    if solution is None:   # no factors, or too far from K: factorise K itself
        factors = factorize(matrix.tocsc(), strict=False)
        solution = None if factors is None else refined_solve(matrix, factors, target)
        made = (factors, matrix)
    if solution is None:
        return None
    members = np.flatnonzero(stable)
    mode = np.zeros((n, d))
    mode[members[1:]] = solution[:-1].reshape(-1, d)
    return mode, made


def refined_solve(matrix: sp.csr_matrix, factors: Factors, rhs: np.ndarray,
                  normwise: bool = False) -> np.ndarray | None:
    """The solution of matrix x = rhs from factors of a nearby matrix, by iterative
    refinement to a componentwise backward error of `REFINEMENT_TOLERANCE` (as
    `calippso.newton` does for the forces); None when `MAX_REFINEMENTS` steps do not reach it.

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


def least_norm_solve(jacobian: sp.csr_matrix, rhs: np.ndarray,
                     factors: Factors | None = None) -> tuple[np.ndarray, Factors] | None:
    """The least-norm solution t of J t = rhs, shape (columns,), from the sparse symmetric
    system [[I, Jᵀ], [J, 0]] [t; λ] = [0; rhs], and the factors that gave it: `factors` (of
    a nearby system) when their refined solve reaches round-off, else new ones. None when
    the system is singular (the rows of J are dependent: a self-stress)."""
    columns = jacobian.shape[1]
    system = sp.bmat([[sp.identity(columns), jacobian.T], [jacobian, None]], format="csc")
    rows = system.tocsr()
    full_rhs = np.concatenate([np.zeros(columns), rhs])
    if factors is not None:
        solution = refined_solve(rows, factors, full_rhs)
        if solution is not None:
            return solution[:columns], factors
    factors = factorize(system, strict=False)
    solution = None if factors is None else refined_solve(rows, factors, full_rhs)
    return None if solution is None else (solution[:columns], factors)


def onto_contacts(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                  i: np.ndarray, j: np.ndarray, stable: np.ndarray,
                  gamma: float | None = None) -> tuple[np.ndarray, float] | None:
    """The configuration nearest to `positions` at which every pair (i, j) touches, by
    least-norm Gauss–Newton steps (`least_norm_solve`).

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (mean diameters); the first stable particle stays pinned.
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    i, j : ndarray, shape (M,), int
        Pairs of stable particles, with independent rows (at most as many as unknowns).
    stable : ndarray, shape (N,), bool
    gamma : float or None
        The inflation at which the pairs touch (|r_c|²/σ_c² = Γ); None: Γ is an unknown too
        (each step is least-norm in positions and Γ), from 1.

    Returns
    -------
    (ndarray, float) or None
        The positions, shape (N, d), wrapped into the box, and Γ, once every
        | |r_c|²/σ_c² − Γ | ≤ `RESIDUAL_TOLERANCE`; None when the steps exceed
        `MAX_CORRECTION`, do not converge in `MAX_ITERATIONS`, or the rows are dependent.
    """
    d = positions.shape[1]
    movable = np.flatnonzero(stable)[1:]
    sigma = 0.5 * (diameters[i] + diameters[j])
    moved = positions.copy()
    inflation = 1.0 if gamma is None else gamma
    factors = None

    def residual_and_vectors() -> tuple[np.ndarray, np.ndarray]:
        vectors = minimum_image(moved[i] - moved[j], box)
        return np.einsum("md,md->m", vectors, vectors) / sigma**2 - inflation, vectors

    for _ in range(MAX_ITERATIONS):
        residual, vectors = residual_and_vectors()
        if float(np.abs(residual).max(initial=0.0)) <= RESIDUAL_TOLERANCE:
            return wrap(moved, box), inflation
        jacobian = network_jacobian(vectors, sigma, i, j, stable)
        if gamma is not None:   # Γ held: its column leaves
            jacobian = jacobian[:, :-1].tocsr()
        solved = least_norm_solve(jacobian, -residual, factors)
        if solved is None:
            return None
        correction, factors = solved
        shift = correction[:movable.size * d]
        largest = float(np.abs(shift).max(initial=0.0))
        if not largest <= MAX_CORRECTION:
            return None
        moved[movable] += shift.reshape(-1, d)
        if gamma is None:
            inflation += float(correction[-1])
        if largest < STEP_TOLERANCE:
            residual, _ = residual_and_vectors()
            worst = float(np.abs(residual).max(initial=0.0))
            return (wrap(moved, box), inflation) if worst <= RESIDUAL_TOLERANCE else None
    return None


def find_closing_pairs(search: NeighborSearch, keys: np.ndarray, stable: np.ndarray,
                       mode: np.ndarray, gamma_rate: float = 1.0
                       ) -> tuple[Pairs, np.ndarray, np.ndarray] | None:
    """The ratio test: the pairs of stable particles outside a network (pair keys
    i N + j, shape (M,)) that close along its floppy mode, in the order to try them
    (Harris's choice first, `_harris_choice`, then by step and key).

    Pairs within `NEAR_GAP` of contact are read first, farther ones (up to `MAX_NEAR_GAP`,
    and within half the smallest periodic side) while the first step could close a pair
    beyond them (`_reach`).

    Parameters
    ----------
    mode : ndarray, shape (N, d)
        The displacement of every particle per unit step (mean diameters).
    gamma_rate : float
        dΓ per unit step (Γ relative to the inflation of `search`'s diameters): 1 for a mode
        normalised to dΓ = 1, the steps being inflations; a singular network's null vector
        (`_repair_singular`) may have a small or vanishing one.

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
        steps = _closing_steps(near, mode, gamma_rate)
        order = np.lexsort((near.i * n + near.j, steps))   # smallest step, then Bland
        order = order[np.isfinite(steps[order])]
        if order.size and _reach(steps[order[0]], mode, search, gamma_rate) < near_gap:
            break
        if near_gap >= widest:
            return None
        near_gap = min(near_gap * NEAR_GAP_WIDENING, widest)
    first = _harris_choice(near, mode, steps, order, gamma_rate)
    return near, steps, np.concatenate([[first], order[order != first]])


def _harris_choice(pairs: Pairs, mode: np.ndarray, steps: np.ndarray,
                   order: np.ndarray, gamma_rate: float = 1.0) -> int:
    """The pair that closes first, by Harris's ratio test: among the pairs that close before
    the smallest step relaxed by `HARRIS_SLACK` (pairs within round-off of contact close
    together), the one that closes fastest along the mode, so that the new network is the
    best conditioned; ties to the smallest pair key (`order` is by step, then key)."""
    rates = -_closing_rates(pairs.subset(order), mode, gamma_rate)
    phi = (pairs.distances[order] / pairs.sigma[order]) ** 2 - 1.0
    relaxed = float(np.min((np.maximum(phi, 0.0) + HARRIS_SLACK) / rates))
    within = steps[order] <= relaxed
    return int(order[np.flatnonzero(within)[np.argmax(rates[within])]])


def _closing_rates(pairs: Pairs, mode: np.ndarray, gamma_rate: float = 1.0) -> np.ndarray:
    """dΦ_q per unit step along a mode whose Γ grows by `gamma_rate` per step, shape (P,):
    Φ_q = |r_q|²/σ_q² − Γ (negative: closing)."""
    relative = mode[pairs.i] - mode[pairs.j]
    return 2.0 * np.einsum("pd,pd->p", pairs.vectors, relative) / pairs.sigma**2 - gamma_rate


def _closing_steps(pairs: Pairs, mode: np.ndarray, gamma_rate: float = 1.0) -> np.ndarray:
    """The step δ_q = Φ_q / (−dΦ_q/dstep) at which each pair closes along the mode
    (linearised), shape (P,); +inf for pairs that open. Pairs that already touch close at 0."""
    rates = _closing_rates(pairs, mode, gamma_rate)
    phi = (pairs.distances / pairs.sigma) ** 2 - 1.0
    steps = np.full(len(pairs), np.inf)
    closing = rates < 0
    steps[closing] = np.maximum(phi[closing], 0.0) / -rates[closing]
    return steps


def _reach(step: float, mode: np.ndarray, search: NeighborSearch,
           gamma_rate: float = 1.0) -> float:
    """An upper bound on how much a relative gap can shrink over a step along the mode: the
    growth of the diameters plus twice the largest move, relative to the smallest
    diameter."""
    largest_move = float(np.sqrt(np.einsum("nd,nd->n", mode, mode)).max(initial=0.0))
    return step * (0.5 * abs(gamma_rate) + 2.0 * largest_move / float(search.diameters.min()))


def outside_pairs(search: NeighborSearch, keys: np.ndarray, stable: np.ndarray,
                  near_gap: float) -> Pairs:
    """The pairs of `stable` particles within `near_gap` of contact that are not contacts
    (pair keys i N + j, shape (M,))."""
    n = stable.shape[0]
    pairs = search.pairs_within(float(search.diameters.max()) * (1.0 + near_gap))
    outside = (~np.isin(pairs.i * n + pairs.j, keys) & stable[pairs.i]
               & stable[pairs.j] & (pairs.gaps < near_gap))
    return pairs.subset(outside)


def _leaving_contacts(vertex: _Vertex, bland: bool) -> np.ndarray:
    """The contacts to release, in the order to try them: the non-positive forces, most
    negative first; on a degenerate stretch of the path only the one of smallest pair key
    (Bland's rule)."""
    forces = vertex.refinement.forces
    candidates = np.flatnonzero(forces <= MIN_FORCE_RATIO * float(forces.max()))
    if bland:
        return candidates[[np.argmin(vertex.keys[candidates])]]
    return candidates[np.argsort(forces[candidates], kind="stable")]


def _network_digest(vertex: _Vertex) -> bytes:
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


def describe_path(path: PivotPath) -> str:
    """One clause on a path for the run's notes: floppy modes closed, pivots (and the repairs
    of a singular network among them), time, contacts swapped, largest growth of one
    pivot."""
    closed = ""
    if path.closed:
        pairs = ", ".join(f"{pair}" for pair in path.closed[:LISTED_SWAPS])
        more = f" and {len(path.closed) - LISTED_SWAPS} more" if len(
            path.closed) > LISTED_SWAPS else ""
        closed = (f"{len(path.closed)} floppy mode(s) of the hypostatic network closed "
                  f"(pairs {pairs}{more}), then ")
    listed = ", ".join(f"{swap.released}->{swap.closed}" for swap in path.swaps[:LISTED_SWAPS])
    more = f" and {path.pivots - LISTED_SWAPS} more" if path.pivots > LISTED_SWAPS else ""
    degenerate = f" ({path.degenerate} degenerate)" if path.degenerate else ""
    repaired = (f"singular Jacobian ({path.repairs} of them opened a redundant contact and "
                f"closed a floppy mode) and its " if path.repairs else "")
    if not path.pivots:
        return f"{closed}no contact pivot was needed ({path.seconds:.2f} s)"
    return (f"{closed}{path.pivots} contact pivot(s){degenerate} in {path.seconds:.2f} s "
            f"repaired the network's {repaired}non-positive forces (released->closed: "
            f"{listed}{more}; largest growth of one pivot sqrt(Gamma)-1 = "
            f"{path.largest_growth:.1e})")
