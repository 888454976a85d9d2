"""cvxpy backend: the same LP stated in cvxpy (solved by Clarabel), for users who want to
modify the model (add constraints, change the objective) in a modelling language."""

from __future__ import annotations

import time
import warnings

import cvxpy as cp
import numpy as np

from ..lp import LinearProgram
from ..settings import JamSettings
from .base import LPSolution
from .clarabel import TOLERANCE


def build_problem(lp: LinearProgram) -> tuple[cp.Problem, cp.Variable, cp.Constraint]:
    """The LP as a cvxpy problem: (problem, free variables with γ last, pair constraint)."""
    free = lp.col_upper > lp.col_lower
    x = cp.Variable(int(free.sum()))
    lower, upper = lp.col_lower[free], lp.col_upper[free]
    has_upper = np.isfinite(upper)
    pairs = lp.matrix[:, free] @ x >= lp.row_lower
    constraints = [pairs, x >= lower]
    if has_upper.any():
        constraints.append(x[np.flatnonzero(has_upper)] <= upper[has_upper])
    return cp.Problem(cp.Maximize(x[-1]), constraints), x, pairs


def solve(lp: LinearProgram, settings: JamSettings, warm_start=None) -> LPSolution:
    """Build the cvxpy problem and solve it with Clarabel at tight tolerances. `warm_start` is
    accepted for a uniform interface and ignored (interior point has no basis to reuse)."""
    start = time.perf_counter()
    problem, x, pairs = build_problem(lp)
    try:
        with warnings.catch_warnings():
            # "Solution may be inaccurate": the loop checks every solution itself.
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL, tol_gap_abs=TOLERANCE, tol_gap_rel=TOLERANCE,
                          tol_feas=TOLERANCE, tol_ktratio=1e-9, direct_solve_method="faer")
    except cp.error.SolverError as error:
        return LPSolution(x=np.full(lp.n_cols, np.nan), duals=np.full(lp.n_rows, np.nan),
                          optimal=False, status=f"solver error: {error}",
                          seconds=time.perf_counter() - start, vertex=False, solver="cvxpy")
    optimal = problem.status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)
    full = np.zeros(lp.n_cols)
    if optimal:
        full[lp.col_upper > lp.col_lower] = x.value
        duals = np.maximum(np.asarray(pairs.dual_value, dtype=float), 0.0)
    else:
        full[:] = np.nan
        duals = np.full(lp.n_rows, np.nan)
    return LPSolution(x=full, duals=duals, optimal=optimal, status=str(problem.status),
                      seconds=time.perf_counter() - start, vertex=False, solver="cvxpy")
