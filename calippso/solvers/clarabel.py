"""Clarabel backend (native API): interior point at tight tolerances, faer sparse LDLᵀ."""

from __future__ import annotations

import time
from dataclasses import dataclass

import clarabel
import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from ..lp import LinearProgram
from ..settings import JamSettings
from .base import Basis, LPSolution
from .conic_form import conic_form

#: Clarabel statuses whose solution the loop may use (it checks every solution itself).
_SOLVED = ("Solved", "AlmostSolved")


@dataclass(frozen=True)
class ClarabelOptions:
    """Options of the Clarabel backend (and of the cvxpy one, which solves with Clarabel).

    Attributes
    ----------
    tolerance : float
        Clarabel's absolute and relative duality gap and feasibility tolerances: tight enough
        that contacts are identified unambiguously (looser ones gave non-isostatic contact
        counts).
    ktratio_tolerance : float
        Clarabel's bound on the κ/τ ratio that declares infeasibility.
    direct_solve_method : str
        Clarabel's sparse LDLᵀ factorisation, "faer" or "qdldl" (``bench/lp_solvers.py``
        times both on one LP of the loop).
    """

    tolerance: float = 1e-11
    ktratio_tolerance: float = 1e-9
    direct_solve_method: str = "faer"

    @classmethod
    def from_settings(cls, settings: JamSettings) -> "ClarabelOptions":
        """The options of a run: the defaults (no `JamSettings` field applies)."""
        return cls()


def solve(lp: LinearProgram, options: ClarabelOptions, warm_start: Basis | None = None
          ) -> LPSolution:
    """Solve with Clarabel; duals of the pair rows are the contact multipliers. `warm_start` is
    accepted for a uniform interface and ignored (interior point has no basis to reuse).

    Raises
    ------
    SolverError
        If Clarabel raised (out of memory, an internal error).
    """
    start = time.perf_counter()
    form = conic_form(lp)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.direct_solve_method = options.direct_solve_method
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = options.tolerance
    settings.tol_ktratio = options.ktratio_tolerance
    n_free = form.cost.shape[0]
    try:
        solver = clarabel.DefaultSolver(sp.csc_matrix((n_free, n_free)), form.cost, form.matrix,
                                        form.rhs, [clarabel.NonnegativeConeT(form.rhs.shape[0])],
                                        settings)
        solution = solver.solve()
    except (RuntimeError, MemoryError) as error:
        raise SolverError(f"Clarabel raised {type(error).__name__}: {error}") from error
    status = str(solution.status)
    optimal = status in _SOLVED
    x = form.full_x(np.asarray(solution.x)) if optimal else np.full(lp.n_cols, np.nan)
    duals = np.asarray(solution.z)[:form.n_pair_rows] if optimal else np.full(lp.n_rows, np.nan)
    return LPSolution(x=x, duals=np.maximum(duals, 0.0), optimal=optimal, status=status,
                      seconds=time.perf_counter() - start, vertex=False, solver="clarabel")


class ClarabelBackend:
    """The "clarabel" backend (see `Backend`)."""

    name = "clarabel"
    options_type = ClarabelOptions

    def options(self, settings: JamSettings) -> ClarabelOptions:
        return ClarabelOptions.from_settings(settings)

    def validate(self, options: ClarabelOptions) -> None:
        """Nothing to check: every Clarabel build has what the options name."""

    def solve(self, lp: LinearProgram, options: ClarabelOptions,
              warm_start: Basis | None = None) -> LPSolution:
        return solve(lp, options, warm_start)


#: The registered instance (`calippso.solvers.registry`).
BACKEND = ClarabelBackend()
