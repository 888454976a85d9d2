"""The repair of a singular network: isostatic by count, short of one rank.

`singular_vectors` finds the floppy mode and the self-stress from one sparse LU of the
bordered Jacobian; `repair_singular` opens a redundant contact that the self-stress marks,
follows the floppy mode with Γ not decreasing, and closes the pair of the ratio test. The
vertex it reaches is the first of a pivot path (`Swap.repaired`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from ...geometry.neighbors import NeighborSearch, Pairs
from ...network import NEWTON_OVERLAP_TOLERANCE
from ..newton import RESIDUAL_TOLERANCE, network_jacobian, refine_isostatic
from ...geometry.packing import minimum_image
from ...geometry.rattlers import remove_rattlers
from ..sparse_lu import Factors, factorize
from .geometry import (NEAR_GAP, RATIO_CANDIDATES, find_closing_pairs, onto_contacts,
                       outside_pairs, rattlers_out_of_the_way, refined_solve)
from .vertex import DEGENERATE_STEP, Basis, Swap, Vertex

__all__ = ["singular_vectors", "repair_singular", "BORDER_SEED", "SINGULAR_RESIDUAL",
           "UNDECIDED_SIGN", "REDUNDANT_RATIO", "REPAIR_TRIES"]

#: Seed of the random border of the rank-revealing system (`singular_vectors`): fixed, so
#: that a repair is reproducible.
BORDER_SEED = 34
#: A network's Jacobian is singular (and its start is repaired, `repair_singular`) when
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
#: Redundant contacts tried in turn by a repair (`repair_singular`), each with the first
#: pairs of the ratio test; each try is a Newton solve.
REPAIR_TRIES = 3


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
        The contact Jacobian of a network (`calippso.certification.newton.network_jacobian`), its last
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


def repair_singular(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                     i: np.ndarray, j: np.ndarray, stable: np.ndarray
                     ) -> tuple[tuple[Vertex, Swap, int] | None, str]:
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
                     ) -> tuple[tuple[Vertex, Swap] | None, int]:
    """The vertex of a repair (`repair_singular`): Newton on the network with contact
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
    separated = rattlers_out_of_the_way(moved, refined, now_stable)
    if separated is None:
        return None, refined.factorizations
    basis = (Basis(*refined.factorization, stable) if refined.factorization is not None
             and np.array_equal(now_stable, stable) else None)
    swap = Swap((int(i[released]), int(j[released])),
                (int(near.i[closing]), int(near.j[closing])), max(growth, 0.0),
                int(np.count_nonzero(now_rattlers & stable)), repaired=True)
    return (Vertex(i_new, j_new, now_stable, separated, basis), swap), refined.factorizations
