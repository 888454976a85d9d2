"""One LP without crossover against N: what `jam(..., crossover="off")` pays per LP.

For each input, the first LP that `calippso.jam` builds (its rows at the first bound, one
particle pinned) is solved by HiGHS's interior point without crossover, as the loop solves
it; then its network is read by strict complementarity (`calippso.complementarity`) and,
when isostatic, solved by Newton from the moved positions. Inputs are soft-sphere quenches
(`generators.soft_quench`, seed --seed, at the default target pressure) made once and kept
in --cache, or files given with --input. --tile K repeats an input K times along every
axis (N K^d particles), for an LP of that size when no quench of it is at hand. Run from
the repository root:

    python bench/interior_lp.py --cases 3:1024 3:2048 3:4096 3:8192 --cache DIR
    python bench/interior_lp.py --cases 3:2048 --tile 2 --cache DIR   # N = 16384
    python bench/interior_lp.py --cases 3:1024 --tolerance 1e-8 1e-10 1e-12 --json t.json
    python bench/interior_lp.py --cases 3:8192 --threads 2 --cache DIR
    python bench/interior_lp.py --cases 3:8192 --cache DIR --hipo hipo_system=normaleq

--hipo KEY=VALUE sets HiGHS options on the solve (HiPO's Newton system "augmented" or
"normaleq", its ordering "metis", "amd" or "rcm", its block size), each case once per
setting given, for a comparison with HiGHS's own choice.

Columns: N, d, the LP's rows and columns, the interior point, seconds inside HiGHS, of which
HiPO's analysis (ordering), its iterations, the factor's nonzeros, fill-in and flops (HiPO's
log; IPX reports none), seconds to read complementarity and its margin (decades by which
the least clear row was read apart), contacts read, isostaticity gap after rattler removal,
and the seconds of the Newton stage on that network (positive forces or not, and how many
are not).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
import time

import highspy
import numpy as np

import calippso
from calippso.complementarity import read_complementarity
from calippso.ilp import initial_step_bound, median_gap
from calippso.lp import build_lp, select_pairs
from calippso.geometry.neighbors import NeighborSearch
from calippso.certification.newton import MIN_FORCE_RATIO, pinned_coordinates, refine_isostatic
from calippso.geometry.packing import Packing, wrap
from calippso.settings import JamSettings
from calippso.solvers.highs import (HighsOptions, _interior_solution, _quiet_highs,
                                    interior_point_for)
from calippso.step import analyse

#: HiPO's log lines read into the table: label in the log -> column.
HIPO_LOG = {"Threads": "threads", "Analyse time": "analyse_s", "Nnz": "factor_nnz",
            "Fill-in": "fill_in", "Flops": "flops"}


def quench(d: int, n: int, seed: int, cache: str) -> tuple[Packing, float]:
    """The quench of `n` spheres in `d` dimensions (read from `cache` when made before) and
    the seconds spent making it (0 when read)."""
    import generators

    pressure = generators.default_target_pressure(n, d)
    path = os.path.join(cache, f"quench_d{d}_n{n}_p{pressure:g}_seed{seed}.npz")
    if os.path.exists(path):
        return calippso.read(path), 0.0
    began = time.perf_counter()
    made = generators.soft_quench(generators.diameters.monodisperse(n), d, seed=seed,
                                  target_pressure=pressure)
    packing = made.packing
    np.savez(path, positions=packing.positions, diameters=packing.diameters, box=packing.box,
             contacts=made.contacts)
    return packing, time.perf_counter() - began


def tiled(packing: Packing, k: int) -> Packing:
    """`packing` repeated `k` times along every axis of its periodic box."""
    if k == 1:
        return packing
    d = packing.d
    shifts = np.stack(np.meshgrid(*[np.arange(k)] * d, indexing="ij"), -1).reshape(-1, d)
    positions = (packing.positions[None] + shifts[:, None] * packing.box).reshape(-1, d)
    return Packing(positions, np.tile(packing.diameters, len(shifts)), packing.box * k)


def one_lp(packing: Packing, tolerance: float, interior_point: str, threads: int = 0,
           highs_options: dict[str, str | int] | None = None) -> dict:
    """Solve the first LP of `jam` on `packing` without crossover and read it (module doc);
    `highs_options` are set on HiGHS before the solve."""
    scale = packing.mean_diameter
    box = packing.box / scale
    positions, diameters = wrap(packing.positions / scale, box), packing.diameters / scale
    search = NeighborSearch(positions, diameters, box)
    settings = JamSettings(crossover="off")
    bound = initial_step_bound(median_gap(search), settings)
    fixed = pinned_coordinates(positions, box, np.ones(packing.n, bool), packing.boundaries)
    lp = build_lp(select_pairs(search, bound), packing.n, packing.d, bound, fixed)
    options = HighsOptions(crossover=False, interior_point=interior_point,
                           interior_optimality_tolerance=tolerance)
    with tempfile.TemporaryDirectory() as folder:
        log = os.path.join(folder, "highs.log")
        highs = _quiet_highs()
        highs.setOptionValue("primal_feasibility_tolerance", options.feasibility_tolerance)
        highs.setOptionValue("dual_feasibility_tolerance", options.feasibility_tolerance)
        highs.setOptionValue("output_flag", True)   # HiPO logs to the console only
        if threads:
            highs.setOptionValue("threads", threads)
        for key, value in (highs_options or {}).items():
            if highs.setOptionValue(key, value) != highspy.HighsStatus.kOk:
                raise SystemExit(f"HiGHS refused the option {key}={value!r}")
        began = time.perf_counter()
        with open(log, "w") as sink:
            sys.stdout.flush()
            saved = os.dup(1)
            os.dup2(sink.fileno(), 1)
            try:
                highs.passModel(_model(lp))
                solution = _interior_solution(highs, lp, options, began)
            finally:
                os.dup2(saved, 1)
                os.close(saved)
        highs.setOptionValue("output_flag", False)
        text = open(log).read()
    row = {"n": packing.n, "d": packing.d, "rows": lp.n_rows, "cols": lp.n_cols,
           "highs_options": highs_options or {},
           "bound": bound, "tolerance": tolerance,
           "method": interior_point_for(lp, interior_point), "status": solution.status,
           "solver_s": solution.seconds, "ipm_iterations": solution.ipm_iterations}
    for label, column in HIPO_LOG.items():
        found = re.findall(rf"^{label}:\s+(\S+)", text, flags=re.M)
        row[column] = float(found[-1]) if found else float("nan")
    began = time.perf_counter()
    reading = read_complementarity(lp, solution)
    taken = analyse(lp, solution, settings)
    row.update(read_s=time.perf_counter() - began, margin=reading.margin,
               contacts=taken.n_contacts,
               isostaticity_gap=int(taken.n_contacts
                                    - packing.d * (packing.n - taken.rattlers.sum() - 1) - 1))
    row["newton_s"], row["positive"], row["nonpositive"] = float("nan"), None, None
    if row["isostaticity_gap"] == 0:
        network = taken.network()
        moved = wrap(positions + taken.displacements, box)
        began = time.perf_counter()
        refined = refine_isostatic(moved, diameters * np.sqrt(1 + solution.gamma), box,
                                   network.i, network.j, ~network.rattlers)
        row["newton_s"] = time.perf_counter() - began
        row["positive"] = None if refined is None else bool(refined.positive)
        row["nonpositive"] = (None if refined is None else int(np.count_nonzero(
            refined.forces <= MIN_FORCE_RATIO * refined.forces.max())))
    return row


def _model(lp):
    from calippso.solvers.highs import highs_model

    return highs_model(lp)


def _option(text: str) -> tuple[str, str | int]:
    """KEY=VALUE as a HiGHS option (integers as int)."""
    key, _, value = text.partition("=")
    return key, int(value) if value.lstrip("-").isdigit() else value


def print_row(row: dict) -> None:
    print(f"{row['n']:6d} {row['d']:2d} {row['rows']:7d} {row['cols']:7d} {row['method']:>5} "
          f"{row['tolerance']:7.0e} {row['solver_s']:8.2f} {row['analyse_s']:7.2f} "
          f"{row['ipm_iterations']:4d} {row['factor_nnz']:9.2e} {row['fill_in']:6.1f} "
          f"{row['flops']:8.1e} {row['threads']:3.0f} {row['read_s']:6.3f} {row['margin']:6.2f} "
          f"{row['contacts']:7d} {row['isostaticity_gap']:5d} {row['newton_s']:7.2f} "
          f"{row['positive']} ({row['nonpositive']}) "
          f"{' '.join(f'{k}={v}' for k, v in row['highs_options'].items())}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", nargs="*", default=["3:1024"], help="d:N quenches")
    parser.add_argument("--input", nargs="*", default=[], help="packing files instead")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--cache", default="", help="folder for the quenches")
    parser.add_argument("--tile", type=int, default=1)
    parser.add_argument("--tolerance", type=float, nargs="*",
                        default=[HighsOptions().interior_optimality_tolerance])
    parser.add_argument("--interior-point", default="auto", choices=["auto", "ipx", "hipo"])
    parser.add_argument("--threads", type=int, default=0,
                        help="HiGHS's threads (0: as jam runs it, "
                             "calippso.solvers.highs.highs_threads)")
    parser.add_argument("--hipo", nargs="*", default=[], metavar="KEY=VALUE",
                        help="HiGHS options to compare, one setting each (module doc)")
    parser.add_argument("--json", default="")
    args = parser.parse_args()
    settings = [None] + [dict([_option(text)]) for text in args.hipo]
    inputs = [(path, lambda p=path: (calippso.read(p), 0.0)) for path in args.input]
    for case in args.cases if not args.input else []:
        d, n = map(int, case.split(":"))
        inputs.append((case, lambda d=d, n=n: quench(d, n, args.seed, args.cache or ".")))
    print(f"{'N':>6} {'d':>2} {'rows':>7} {'cols':>7} {'ipm':>5} {'tol':>7} {'LP s':>8} "
          f"{'anal s':>7} {'its':>4} {'factor':>9} {'fill':>6} {'flops':>8} {'thr':>3} "
          f"{'read s':>6} "
          f"{'margin':>6} {'Nc':>7} {'iso':>5} {'Newt s':>7} positive")
    rows = []
    for name, make in inputs:
        packing, made = make()
        packing = tiled(packing, args.tile)
        for tolerance in args.tolerance:
            for highs_options in settings:
                row = {"input": name, "tile": args.tile, "make_s": made,
                       **one_lp(packing, tolerance, args.interior_point, args.threads,
                                highs_options)}
                print_row(row)
                rows.append(row)
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(rows, handle, indent=1)


if __name__ == "__main__":
    main()
