"""One CALiPPSO LP, many solvers: prints the time of each on the same rows.

The LP is the one `calippso.jam` builds at LP number --lp of the run from our LS input
(d = 3, N = --n, reduced pressure 1e5, seed 1), in the middle of the approach to jamming.
Run from the repository root:

    python bench/lp_solvers.py                 # N = 1024, LP 10

Columns: solver and options, seconds, status, optimum γ, simplex and interior-point
iterations (HiGHS), or interior-point iterations and seconds per iteration (Clarabel).
"""

from __future__ import annotations

import argparse
import time

import clarabel
import highspy
import numpy as np
import scipy.sparse as sp

import calippso
import calippso.ilp
from calippso.lp import LinearProgram
from calippso.solvers.conic_form import conic_form
from calippso.solvers.highs import _model

TOLERANCES = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}

HIGHS_VARIANTS = {
    "HiGHS IPM + crossover": {"solver": "ipm", "run_crossover": "on",
                              "ipm_optimality_tolerance": 1e-12},
    "HiGHS IPM, no crossover": {"solver": "ipm", "run_crossover": "off",
                                "ipm_optimality_tolerance": 1e-12},
    "HiGHS dual simplex": {"solver": "simplex", "simplex_strategy": 1},
    "HiGHS parallel simplex": {"solver": "simplex", "simplex_strategy": 4},
    "HiGHS PDLP": {"solver": "pdlp"},
}


def capture_lp(n: int, index: int) -> LinearProgram:
    """The LP number `index` (0-based) of `jam` on our LS input."""
    import generators

    start = generators.lubachevsky_stillinger(generators.diameters.monodisperse(n), d=3,
                                              target_pressure=1e5, seed=1).packing
    captured: list[LinearProgram] = []
    real = calippso.ilp.get_solver

    def recording(name):
        solve = real(name)

        def wrapper(lp, settings, warm_start=None):
            captured.append(lp)
            return solve(lp, settings, warm_start=warm_start)
        return wrapper

    calippso.ilp.get_solver = recording
    try:
        calippso.jam(start, max_iters=index + 1, newton=False)
    finally:
        calippso.ilp.get_solver = real
    return captured[index]


def time_highs(lp: LinearProgram, options: dict) -> tuple[float, str, float, str]:
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", False)
    for key, value in {**TOLERANCES, **options}.items():
        highs.setOptionValue(key, value)
    highs.passModel(_model(lp))
    start = time.perf_counter()
    highs.run()
    seconds = time.perf_counter() - start
    info = highs.getInfo()
    return (seconds, highs.modelStatusToString(highs.getModelStatus()),
            -info.objective_function_value,
            f"simplex {info.simplex_iteration_count}, ipm {info.ipm_iteration_count}")


def time_clarabel(lp: LinearProgram, method: str,
                  without_gamma: bool = False) -> tuple[float, str, float, str]:
    """Clarabel on the LP; `without_gamma` drops the dense γ column and puts a small random
    cost on the displacements instead, to time the factorisation without that column."""
    form = conic_form(lp)
    matrix, cost = form.matrix, form.cost
    if without_gamma:
        matrix = matrix[:, :-1]
        cost = 1e-3 * np.random.default_rng(0).standard_normal(matrix.shape[1])
    options = clarabel.DefaultSettings()
    options.verbose = False
    options.direct_solve_method = method
    options.tol_gap_abs = options.tol_gap_rel = options.tol_feas = 1e-11
    size = cost.shape[0]
    start = time.perf_counter()
    solver = clarabel.DefaultSolver(sp.csc_matrix((size, size)), cost, matrix, form.rhs, [clarabel.NonnegativeConeT(form.rhs.shape[0])],
                                    options)
    solution = solver.solve()
    seconds = time.perf_counter() - start
    return (seconds, str(solution.status), np.nan if without_gamma else -solution.obj_val,
            f"ipm {solution.iterations}, {seconds / max(solution.iterations, 1):.2f} s each")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--lp", type=int, default=10, help="which LP of the run (0-based)")
    args = parser.parse_args()

    lp = capture_lp(args.n, args.lp)
    print(f"LP {args.lp} of the N = {args.n}, d = 3 LS run: {lp.n_rows} rows, {lp.n_cols} "
          f"columns, {lp.matrix.nnz} non-zeros")
    print(f"{'solver':<28} {'seconds':>8} {'status':>10} {'gamma':>14}  iterations")
    rows = [(name, time_highs(lp, options)) for name, options in HIGHS_VARIANTS.items()]
    rows += [(f"Clarabel ({method})", time_clarabel(lp, method)) for method in ("faer", "qdldl")]
    rows.append(("Clarabel (faer), no γ column", time_clarabel(lp, "faer", without_gamma=True)))
    for name, (seconds, status, gamma, iterations) in rows:
        print(f"{name:<28} {seconds:>8.2f} {status:>10} {gamma:>14.6e}  {iterations}",
              flush=True)


if __name__ == "__main__":
    main()
