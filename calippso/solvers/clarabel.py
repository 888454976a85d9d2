"""Clarabel backend (native API): interior point at tight tolerances, faer sparse LDLᵀ."""

from __future__ import annotations

import time

import clarabel
import numpy as np
import scipy.sparse as sp

from ..lp import LinearProgram
from ..settings import JamSettings
from .base import LPSolution
from .conic_form import conic_form

#: Tolerances tight enough that contacts are identified unambiguously (looser ones gave
#: non-isostatic contact counts).
TOLERANCE = 1e-11


def solve(lp: LinearProgram, settings: JamSettings, warm_start=None) -> LPSolution:
    """Solve with Clarabel; duals of the pair rows are the contact multipliers. `warm_start` is
    accepted for a uniform interface and ignored (interior point has no basis to reuse)."""
    start = time.perf_counter()
    form = conic_form(lp)
    options = clarabel.DefaultSettings()
    options.verbose = False
    options.direct_solve_method = "faer"
    options.tol_gap_abs = options.tol_gap_rel = options.tol_feas = TOLERANCE
    options.tol_ktratio = 1e-9
    n_free = form.cost.shape[0]
    solver = clarabel.DefaultSolver(sp.csc_matrix((n_free, n_free)), form.cost, form.matrix,
                                    form.rhs, [clarabel.NonnegativeConeT(form.rhs.shape[0])],
                                    options)
    solution = solver.solve()
    status = str(solution.status)
    optimal = status in ("Solved", "AlmostSolved")
    x = form.full_x(np.asarray(solution.x)) if optimal else np.full(lp.n_cols, np.nan)
    duals = np.asarray(solution.z)[:form.n_pair_rows] if optimal else np.full(lp.n_rows, np.nan)
    return LPSolution(x=x, duals=np.maximum(duals, 0.0), optimal=optimal, status=status,
                      seconds=time.perf_counter() - start, vertex=False, solver="clarabel")
