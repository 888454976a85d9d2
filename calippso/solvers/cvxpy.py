"""cvxpy backend: the same LP stated in cvxpy (solved by Clarabel), for users who want to
modify the model (add constraints, change the objective) in a modelling language."""

from __future__ import annotations

import time
import warnings

import cvxpy as cp
import numpy as np

from ..errors import SolverError
from ..lp import LinearProgram
from .base import Basis, LPSolution
from .clarabel import ClarabelBackend, ClarabelOptions


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


def solve(lp: LinearProgram, options: ClarabelOptions, warm_start: Basis | None = None
          ) -> LPSolution:
    """Build the cvxpy problem and solve it with Clarabel at the tolerances of `options`.
    `warm_start` is accepted for a uniform interface and ignored (interior point has no basis
    to reuse).

    Raises
    ------
    SolverError
        If cvxpy reports a solver error.
    """
    start = time.perf_counter()
    problem, x, pairs = build_problem(lp)
    try:
        with warnings.catch_warnings():
            # "Solution may be inaccurate": the loop checks every solution itself.
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL, tol_gap_abs=options.tolerance,
                          tol_gap_rel=options.tolerance, tol_feas=options.tolerance,
                          tol_ktratio=options.ktratio_tolerance,
                          direct_solve_method=options.direct_solve_method)
    except cp.error.SolverError as error:
        raise SolverError(f"cvxpy: {error}") from error
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


class CvxpyBackend(ClarabelBackend):
    """The "cvxpy" backend (see `Backend`); its options are Clarabel's."""

    name = "cvxpy"

    def validate(self, options: ClarabelOptions) -> None:
        """Nothing to check: cvxpy ships with Clarabel."""

    def solve(self, lp: LinearProgram, options: ClarabelOptions,
              warm_start: Basis | None = None) -> LPSolution:
        return solve(lp, options, warm_start)


#: The registered instance (`calippso.solvers.registry`).
BACKEND = CvxpyBackend()
