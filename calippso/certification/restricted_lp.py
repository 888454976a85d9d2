"""Which contacts of a hyperstatic candidate network stay closed: the CALiPPSO LP restricted
to the candidate pairs, solved in the space of their self-stresses.

A near-jammed configuration often holds a few more near-contacts than an isostatic network
has contacts (the overlap network of a soft-sphere quench at a small pressure, a gap
spectrum without a clean jump). Which of them open on the way to the jamming point is what
the next LP of the loop would tell: at its optimum only the contacts with a positive dual
stay closed. That LP, with no step bound and only the candidate pairs as rows, is solved
here through its dual, without a sparse LP solver.

In the variables of the Newton stage (`calippso.certification.newton`: positions and Γ, the contact
Jacobian J, shape (M, n) with n = d (N_s − 1) + 1 unknowns and M = n + k rows), the dual of
the restricted LP reads

    minimise  Σ_c y_c (|r_c|²/σ_c² − 1)   subject to   Jᵀ y = (0, …, 0, −1),   y ≥ 0,

where y_c = μ_c σ_c² / (2 |r_c|) is the LP multiplier μ_c of contact c rescaled (the LP rows of
`calippso.lp` are the rows of J times σ_c² / (2 |r_c|)), and Σ_c y_c = 1. Its feasible
set has dimension k only. With a basis B of n rows whose square block J_B is non-singular,
every feasible y is y_p + Z λ: y_p = (J_B⁻ᵀ b, 0) and one column of Z per excess row e,
(−J_B⁻ᵀ J_eᵀ, 1 at e). One sparse LU of J_B (`calippso.certification.sparse_lu`) and k + 1 solves turn
the problem into a dense LP in k variables, which HiGHS solves by cutting planes (only the
rows that can reach zero). At its
vertex, k rows have y = 0: those contacts open, and the others form an isostatic network
whose forces are positive. The Newton stage and its certificate then decide, as for any
guessed network.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

from ..geometry.contacts import isostaticity_gap, remove_rattlers
from ..geometry.neighbors import Pairs
from .newton import network_jacobian
from .sparse_lu import factorize

__all__ = ["MAX_OPEN_CONTACTS", "TOO_FEW", "TOO_MANY", "lp_network"]

#: Largest excess k solved: the null-space directions are M × k numbers (M ~ d N contacts;
#: 200 MB at N = 16384 in d = 3), and a candidate network that far from isostatic is a
#: crystal or a compressed state, not a near-jammed one.
MAX_OPEN_CONTACTS = 512
#: Feasibility and optimality tolerances of the dense LP, with the forces scaled to a mean
#: of one: far below the smallest contact forces of a jammed packing (~1e-4 of the mean at
#: N ~ 10⁴) and far above round-off.
LP_TOLERANCE = 1e-10
#: The first cutting-plane LP holds this many basis rows per excess row, and at least
#: `MIN_FIRST_ROWS`; rows that its solution drives negative (below −`CUT_TOLERANCE`, with
#: multipliers of mean one) are added, for at most `MAX_CUTS` LPs.
ROWS_PER_EXCESS = 16
MIN_FIRST_ROWS = 512
CUT_TOLERANCE = 1e-9
MAX_CUTS = 20
#: Failures of `lp_network`: the pairs hold no positive self-stress, or too many pairs.
TOO_FEW = "no positive self-stress on the candidate pairs"
TOO_MANY = f"more than {MAX_OPEN_CONTACTS} candidate pairs beyond an isostatic network"
#: A multiplier below this fraction of the mean is an open contact at the LP's vertex.
OPEN_FORCE_RATIO = 1e-8


def lp_network(pairs: Pairs, n: int, d: int) -> tuple[np.ndarray | None, str]:
    """The contacts that stay closed at the optimum of the LP restricted to `pairs`.

    Parameters
    ----------
    pairs : Pairs
        Candidate contacts, with their geometry (any length unit; no pair overlapping).
    n, d : int
        Number of particles and dimension.

    Returns
    -------
    closed : ndarray, shape (len(pairs),), bool, or None
        The pairs with a positive multiplier at the optimum (before rattler removal, which
        the caller does); None when there is none.
    failure : str
        Why `closed` is None: `TOO_FEW` when the candidates cannot hold a positive
        self-stress (hypostatic, a singular basis, an infeasible dual: the LP restricted
        to them is unbounded, and pairs are missing), `TOO_MANY` when their excess over
        isostaticity is larger than `MAX_OPEN_CONTACTS`; empty otherwise.
    """
    rattlers, kept = remove_rattlers(n, d, pairs.i, pairs.j)
    stable = ~rattlers
    n_stable = int(stable.sum())
    excess = isostaticity_gap(int(kept.sum()), n_stable, d)
    if excess > MAX_OPEN_CONTACTS:
        return None, TOO_MANY
    if n_stable == 0 or excess < 0:
        return None, TOO_FEW
    rows = np.flatnonzero(kept)
    if excess == 0:
        return kept, ""
    network = pairs.subset(rows)
    jacobian = network_jacobian(network.vectors, network.sigma, network.i, network.j, stable)
    basis = _basis(network, n, d, excess)
    multipliers = None if basis is None else _optimal_multipliers(jacobian, basis,
                                                                   network.gaps)
    if multipliers is None:
        return None, TOO_FEW
    closed = np.zeros(len(pairs), dtype=bool)
    closed[rows] = multipliers > OPEN_FORCE_RATIO * multipliers.mean()
    return closed, ""


def _basis(network: Pairs, n: int, d: int, excess: int) -> np.ndarray | None:
    """`excess` rows to leave out of the basis: the largest gaps first, never one whose removal
    would leave a particle with fewer than d + 1 contacts (boolean mask of the basis rows);
    None if too few rows can go."""
    basis = np.ones(len(network), dtype=bool)
    counts = np.bincount(network.i, minlength=n) + np.bincount(network.j, minlength=n)
    for row in np.argsort(-network.gaps, kind="stable"):
        if excess == 0:
            break
        a, b = network.i[row], network.j[row]
        if counts[a] > d + 1 and counts[b] > d + 1:
            basis[row] = False
            counts[a] -= 1
            counts[b] -= 1
            excess -= 1
    return basis if excess == 0 else None


def _optimal_multipliers(jacobian: sp.csr_matrix, basis: np.ndarray,
                         gaps: np.ndarray) -> np.ndarray | None:
    """The optimal y of the restricted dual (module doc), scaled to a mean of one, shape (M,).

    `gaps` are the relative gaps h_c; the objective weights |r_c|²/σ_c² − 1 = h_c (2 + h_c).
    The dense LP in λ (the excess multipliers, 0 ≤ λ ≤ M since Σ y = M) is solved by cutting
    planes: first with the `_first_rows` basis rows likeliest to reach zero, then with every
    row its solution violates added, until none does.
    """
    m, n_unknowns = jacobian.shape
    factors = factorize(jacobian[basis].tocsc())
    if factors is None:
        return None
    excess_rows = np.flatnonzero(~basis)
    # right-hand sides: b = (0, …, 0, −1) scaled by M (mean multiplier one), then every Jₑᵀ
    right = np.zeros((n_unknowns, 1 + excess_rows.size))
    right[-1, 0] = -float(m)
    right[:, 1:] = jacobian[excess_rows].T.toarray()
    solved = np.asarray(factors.solve(right, trans="T")).reshape(n_unknowns, -1)
    if not np.all(np.isfinite(solved)):
        return None
    particular, directions = solved[:, 0], -solved[:, 1:]   # y on the basis rows
    weights = gaps * (2.0 + gaps)
    weights = weights / (float(np.abs(weights).max()) or 1.0)
    cost = weights[basis] @ directions + weights[excess_rows]
    # the rows likeliest to bind: small multipliers that the directions can cancel
    reach = np.abs(directions).max(axis=1) + np.finfo(float).tiny
    rows = np.argsort(particular / reach, kind="stable")[:_first_rows(excess_rows.size)]
    for _ in range(MAX_CUTS):
        result = linprog(cost, A_ub=-directions[rows], b_ub=particular[rows],
                         bounds=(0.0, float(m)), method="highs",
                         options={"primal_feasibility_tolerance": LP_TOLERANCE,
                                  "dual_feasibility_tolerance": LP_TOLERANCE})
        if result.status != 0:
            return None   # infeasible on a subset of the rows: infeasible
        on_basis = particular + directions @ result.x
        violated = np.flatnonzero(on_basis < -CUT_TOLERANCE)
        if violated.size == 0:
            multipliers = np.zeros(m)
            multipliers[basis] = on_basis
            multipliers[excess_rows] = result.x
            return multipliers
        rows = np.union1d(rows, violated)
    return None


def _first_rows(excess: int) -> int:
    """Rows of the first cutting-plane LP: `ROWS_PER_EXCESS` per excess row, at least
    `MIN_FIRST_ROWS`."""
    return max(MIN_FIRST_ROWS, ROWS_PER_EXCESS * excess)
