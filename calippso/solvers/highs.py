"""HiGHS backend (highspy): interior point followed by crossover, giving a vertex solution."""

from __future__ import annotations

import time

import highspy
import numpy as np

from ..lp import LinearProgram
from ..settings import JamSettings
from .base import LPSolution


def _model(lp: LinearProgram) -> highspy.HighsLp:
    model = highspy.HighsLp()
    model.num_col_ = lp.n_cols
    model.num_row_ = lp.n_rows
    model.sense_ = highspy.ObjSense.kMinimize
    cost = np.zeros(lp.n_cols)
    cost[-1] = -1.0
    model.col_cost_ = cost
    model.col_lower_ = lp.col_lower
    model.col_upper_ = np.where(np.isinf(lp.col_upper), highspy.kHighsInf, lp.col_upper)
    model.row_lower_ = lp.row_lower
    model.row_upper_ = np.full(lp.n_rows, highspy.kHighsInf)
    matrix = model.a_matrix_
    matrix.format_ = highspy.MatrixFormat.kColwise
    matrix.num_col_ = lp.n_cols
    matrix.num_row_ = lp.n_rows
    matrix.start_ = lp.matrix.indptr
    matrix.index_ = lp.matrix.indices
    matrix.value_ = lp.matrix.data
    return model


def solve(lp: LinearProgram, settings: JamSettings) -> LPSolution:
    """Solve with HiGHS interior point + crossover at tight tolerances."""
    start = time.perf_counter()
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", False)
    highs.setOptionValue("solver", "ipm")
    highs.setOptionValue("run_crossover", "on")
    highs.setOptionValue("primal_feasibility_tolerance", settings.feasibility_tolerance)
    highs.setOptionValue("dual_feasibility_tolerance", settings.feasibility_tolerance)
    highs.setOptionValue("ipm_optimality_tolerance", 1e-12)
    highs.passModel(_model(lp))
    highs.run()
    status = highs.getModelStatus()
    solution = highs.getSolution()
    x = np.asarray(solution.col_value, dtype=np.float64)
    duals = np.asarray(solution.row_dual, dtype=np.float64)  # ≥ 0 for active ≥ rows (minimising −γ)
    optimal = status == highspy.HighsModelStatus.kOptimal and x.shape[0] == lp.n_cols
    vertex = highs.getBasis().valid
    return LPSolution(x=x, duals=np.maximum(duals, 0.0) if duals.size else duals,
                      optimal=bool(optimal), status=highs.modelStatusToString(status),
                      seconds=time.perf_counter() - start, vertex=bool(vertex), solver="highs")
