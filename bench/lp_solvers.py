"""One CALiPPSO LP, many solvers: prints the time of each on the same rows.

The LP is the one `calippso.jam` builds at LP number --lp of the run from our LS input
(d = 3, N = --n, reduced pressure 1e5, seed 1), in the middle of the approach to jamming,
or from any packing file given with --input. Run from the repository root:

    python bench/lp_solvers.py                 # N = 1024, LP 10
    python bench/lp_solvers.py --input ../shared/data/mono_N10000_fba1e-3_then_ls1e-2_seed21 \
        --lp 0 --only "IPX + crossover" "HiPO" "Clarabel (faer)" --log  # first LP at N = 10^4
    python bench/lp_solvers.py --lp 0 --only "+ crossover"   # IPX against HiPO, first LP
    python bench/lp_solvers.py --input FILE --lp 10 --warm   # the loop's warm start of LP 10

The HiPO row needs the highspy-extras package (`pip install ".[hipo]"`); without it the row
says that the option is not in this build.

--log prints HiGHS's own log (IPX's factorisation times); --morton renumbers the particles
along a Morton curve first.

--warm times the warm start instead. "from its own optimal basis" restarts the LP at its
optimum: 0 iterations, so its time is what setting up and factorising a basis costs.

Columns: solver and options, seconds, status, optimum γ, simplex and interior-point
iterations (HiGHS), or interior-point iterations and seconds per iteration (Clarabel).
"""

from __future__ import annotations

import argparse
import json
import time

import clarabel
import highspy
import numpy as np
import scipy.sparse as sp

import calippso
from calippso.lp import LinearProgram
from calippso.solvers import Basis, LPAttempt
from calippso.solvers.clarabel import ClarabelOptions
from calippso.solvers.conic_form import conic_form
from calippso.solvers.highs import HighsOptions, highs_model, mapped_basis

#: HiGHS's tolerances as the loop sets them (`HighsOptions` defaults).
TOLERANCES = {"primal_feasibility_tolerance": HighsOptions().feasibility_tolerance,
              "dual_feasibility_tolerance": HighsOptions().feasibility_tolerance}

HIGHS_VARIANTS = {
    "HiGHS IPX + crossover": {"solver": "ipx", "run_crossover": "on",
                              "ipm_optimality_tolerance": 1e-12},
    "HiGHS IPX, no crossover": {"solver": "ipx", "run_crossover": "off",
                                "ipm_optimality_tolerance": 1e-12},
    # only where the highspy-extras package is installed (calippso[hipo])
    "HiGHS HiPO + crossover": {"solver": "hipo", "run_crossover": "on",
                               "ipm_optimality_tolerance": 1e-12},
    "HiGHS dual simplex": {"solver": "simplex", "simplex_strategy": 1},
    "HiGHS dual simplex, LTSSF crash": {"solver": "simplex", "simplex_strategy": 1,
                                        "simplex_crash_strategy": 1},
    "HiGHS primal simplex": {"solver": "simplex", "simplex_strategy": 4},
    "HiGHS primal simplex, LTSSF crash": {"solver": "simplex", "simplex_strategy": 4,
                                          "simplex_crash_strategy": 1},
    "HiGHS primal simplex, Bixby crash": {"solver": "simplex", "simplex_strategy": 4,
                                          "simplex_crash_strategy": 2},
    "HiGHS PDLP": {"solver": "pdlp"},
}


def ls_input(n: int) -> calippso.Packing:
    """Our LS input: d = 3, N = n, reduced pressure 1e5, seed 1."""
    import generators

    return generators.lubachevsky_stillinger(generators.diameters.monodisperse(n), d=3,
                                             target_pressure=1e5, seed=1).packing


def morton_order(packing: calippso.Packing) -> np.ndarray:
    """Particle order along a Morton (Z-order) curve of 2^10 cells per box side."""
    cells = np.floor(packing.wrapped().positions / packing.box * 1024).astype(np.int64)
    cells = cells.clip(0, 1023)
    code = np.zeros(packing.n, dtype=np.int64)
    for bit in range(10):
        for axis in range(packing.d):
            code |= ((cells[:, axis] >> bit) & 1) << (packing.d * bit + axis)
    return np.argsort(code, kind="stable")


class _Captured(Exception):
    """Raised by the `jam` hook once the wanted LP is seen, to end that run there."""


def capture_lp(start: calippso.Packing, index: int) -> tuple[LinearProgram, Basis | None]:
    """The LP number `index` (0-based) of `jam` on `start`, with the warm-start basis the loop
    offers it (None when the loop solves it cold): the first backend call of that LP, as
    ``jam(..., on_lp=...)`` reports it."""
    captured: list[LPAttempt] = []

    def record(attempt: LPAttempt) -> None:
        if attempt.lp_number == index + 1:
            captured.append(attempt)
            raise _Captured

    try:
        calippso.jam(start, max_iters=index + 1, newton=False, network_first="off",
                     fallback_solvers=(), on_lp=record)
    except _Captured:
        pass
    if not captured:
        raise SystemExit(f"the run ended before LP {index}: pick a smaller --lp")
    return captured[0].lp, captured[0].warm_start


def time_highs(lp: LinearProgram, options: dict,
               log: bool = False) -> tuple[float, str, float, str]:
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", log)
    for key, value in {**TOLERANCES, **options}.items():
        if highs.setOptionValue(key, value) != highspy.HighsStatus.kOk:
            return np.nan, f"{key}={value} not in this build", np.nan, ""
    highs.passModel(highs_model(lp))
    start = time.perf_counter()
    highs.run()
    seconds = time.perf_counter() - start
    info = highs.getInfo()
    return (seconds, highs.modelStatusToString(highs.getModelStatus()),
            -info.objective_function_value,
            f"simplex {info.simplex_iteration_count}, ipm {info.ipm_iteration_count}")


def time_warm(lp: LinearProgram, basis: highspy.HighsBasis, options: dict,
              log: bool = False) -> tuple[float, str, float, str]:
    """Primal simplex from `basis` (as the loop's warm start does), with extra `options`."""
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", log)
    for key, value in {**TOLERANCES, "solver": "simplex", "simplex_strategy": 4,
                       **options}.items():
        highs.setOptionValue(key, value)
    highs.passModel(highs_model(lp))
    highs.setBasis(basis)
    start = time.perf_counter()
    highs.run()
    seconds = time.perf_counter() - start
    info = highs.getInfo()
    return (seconds, highs.modelStatusToString(highs.getModelStatus()),
            -info.objective_function_value, f"simplex {info.simplex_iteration_count}")


def optimal_basis(lp: LinearProgram) -> highspy.HighsBasis:
    """The vertex interior point + crossover ends at, as a basis to restart from."""
    highs = highspy.Highs()
    highs.setOptionValue("output_flag", False)
    for key, value in {**TOLERANCES, **HIGHS_VARIANTS["HiGHS IPX + crossover"]}.items():
        highs.setOptionValue(key, value)
    highs.passModel(highs_model(lp))
    highs.run()
    return highs.getBasis()


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
    options.tol_gap_abs = options.tol_gap_rel = options.tol_feas = ClarabelOptions().tolerance
    size = cost.shape[0]
    start = time.perf_counter()
    solver = clarabel.DefaultSolver(sp.csc_matrix((size, size)), cost, matrix, form.rhs, [clarabel.NonnegativeConeT(form.rhs.shape[0])],
                                    options)
    solution = solver.solve()
    seconds = time.perf_counter() - start
    return (seconds, str(solution.status), np.nan if without_gamma else -solution.obj_val,
            f"ipm {solution.iterations}, {seconds / max(solution.iterations, 1):.2f} s each")

#: Options tried on the warm start (--warm), on top of primal simplex.
WARM_VARIANTS = {
    "warm primal (default)": {},
    "warm, Dantzig pricing": {"simplex_primal_edge_weight_strategy": 0},
    "warm, devex pricing": {"simplex_primal_edge_weight_strategy": 1},
    "warm, steepest edge": {"simplex_primal_edge_weight_strategy": 2},
    "warm, row-wise price": {"simplex_price_strategy": 1},
    "warm, update limit 200": {"simplex_update_limit": 200},
    "warm, update limit 2000": {"simplex_update_limit": 2000},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--input", help="a packing file (calippso.read) instead of our LS input")
    parser.add_argument("--lp", type=int, default=10, help="which LP of the run (0-based)")
    parser.add_argument("--only", nargs="+", metavar="NAME",
                        help="run only the solvers whose name contains one of these strings")
    parser.add_argument("--log", action="store_true", help="print HiGHS's log")
    parser.add_argument("--warm", action="store_true",
                        help="time the warm start the loop gives this LP (primal simplex from "
                             "the previous basis, pricing options, and a restart from the LP's "
                             "own optimal basis, which leaves only the set-up and factorisation)")
    parser.add_argument("--morton", action="store_true",
                        help="renumber the particles along a Morton curve first")
    parser.add_argument("--json", help="also write the rows to this JSON file")
    args = parser.parse_args()

    start = calippso.read(args.input) if args.input else ls_input(args.n)
    if args.morton:
        order = morton_order(start)
        start = calippso.Packing(start.positions[order], start.diameters[order], start.box)
    lp, warm_start = capture_lp(start, args.lp)
    print(f"LP {args.lp} of the N = {start.n}, d = {start.d} run: {lp.n_rows} rows, "
          f"{lp.n_cols} columns, {lp.matrix.nnz} non-zeros")
    if args.warm:
        basis = mapped_basis(warm_start, lp) if warm_start is not None else None
        if basis is None:
            raise SystemExit(f"the loop solves LP {args.lp} cold: pick another --lp")
        variants = {name: (lambda options=options: time_warm(lp, basis, options, args.log))
                    for name, options in WARM_VARIANTS.items()}
        own = optimal_basis(lp)
        variants["from its own optimal basis"] = lambda: time_warm(lp, own, {}, args.log)
    else:
        variants = {name: (lambda options=options: time_highs(lp, options, args.log))
                    for name, options in HIGHS_VARIANTS.items()}
        for method in ("faer", "qdldl"):
            variants[f"Clarabel ({method})"] = lambda method=method: time_clarabel(lp, method)
        variants["Clarabel (faer), no γ column"] = lambda: time_clarabel(lp, "faer",
                                                                         without_gamma=True)
    if args.only:
        variants = {name: run for name, run in variants.items()
                    if any(part in name for part in args.only)}
    print(f"{'solver':<34} {'seconds':>8} {'status':>10} {'gamma':>14}  iterations")
    rows = [(name, run()) for name, run in variants.items()]
    for name, (seconds, status, gamma, iterations) in rows:
        print(f"{name:<34} {seconds:>8.2f} {status:>10} {gamma:>14.6e}  {iterations}",
              flush=True)
    if args.json:
        with open(args.json, "w") as stream:
            json.dump([{"solver": name, "seconds": seconds, "status": str(status),
                        "gamma": float(gamma), "iterations": str(iterations),
                        "lp": args.lp, "rows": lp.n_rows, "columns": lp.n_cols}
                       for name, (seconds, status, gamma, iterations) in rows],
                      stream, indent=1)


if __name__ == "__main__":
    main()
