"""Benchmark of `calippso.jam`: prints one table row per (input, backend).

Inputs: the real packings in ../shared/data (when present) and packings made here by the
Lubachevsky–Stillinger generator. Run from the repository root:

    python bench/jam.py                 # default set (d = 3, N ~ 1000, HiGHS)
    python bench/jam.py --backends highs clarabel --ls 2:256 3:1024 4:512
    python bench/jam.py --no-shared --ls --random 3:256:0.2 --set max_step=0.3
    python bench/jam.py --no-shared --seeds 1 2 3 4 5 6 7 8   # the spread over LS inputs
    python bench/jam.py --no-shared --start fb --ls 3:1000 --pressure 1e12 --seeds 1 2 3
    python bench/jam.py --no-shared --pressure 1e7 --final-growth-rate 1e-3   # LS with a slow end
    python bench/jam.py --seeds 1 2 3 4 5 6 7 8 --cache DIR --json jam.json   # keep the inputs

Columns: N, d, backend, LPs, total wall time (s), share of it inside the LP solver,
phi_J, N_c (contacts among stable particles), isostaticity gap, force balance, min gap;
with several runs, a last line with their LPs and wall time in all.
"""

from __future__ import annotations

import argparse
import ast
import json
import time
from pathlib import Path

import calippso
from calippso import protocols
from common import random_sequential_addition

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
SHARED_INPUTS = ["skoge_donev_N1000_d3_p1e12.dat", "mono_N1000_fba1e-3_then_ls1e-2_seed11",
                 "lognormal0.2_N1000_fba1e-3_then_ls1e-2_seed13",
                 "mono_N1000_fba1e-3_phinom0.6_seed11"]


def ls_input(d: int, n: int, pressure: float, seed: int, start: str = "poisson",
             final_growth_rate: float | None = None) -> calippso.Packing:
    """An LS packing compressed to `pressure` (bidisperse 1.4 in d = 2).

    `start` is where LS begins: "poisson" (uniform random centres) or "fb" (a force-biased
    packing, contraction rate 1e-3, the FB → LS protocol of the shared files). With
    `final_growth_rate` the run slows down to it from p = 1e3 on (a slow end).
    """
    import generators

    sizes = (generators.diameters.bidisperse(n, 1.4, 0.5, seed=seed) if d == 2
             else generators.diameters.monodisperse(n))
    begin = ({"start": generators.force_biased(sizes, d, contraction_rate=1e-3, seed=seed).packing}
             if start == "fb" else {"diameters": sizes, "d": d})
    return generators.lubachevsky_stillinger(**begin, target_pressure=pressure, seed=seed,
                                             final_growth_rate=final_growth_rate).packing


def parse_options(pairs: list[str]) -> dict:
    """`key=value` strings as jam options (values parsed as Python literals when possible)."""
    options = {}
    for pair in pairs:
        key, _, value = pair.partition("=")
        try:
            options[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            options[key] = value
    return options


def row(name: str, packing: calippso.Packing, backend: str, max_iters: int,
        options: dict, precompress: float | None = None) -> dict:
    """One run of `jam` (after `calippso.protocols.precompress` to `precompress`, if given,
    whose time counts): the figures of its table row."""
    start = time.perf_counter()
    if precompress is not None:
        packing = protocols.precompress(packing, precompress).packing
    result = calippso.jam(packing, solver=backend, max_iters=max_iters, **options)
    total = time.perf_counter() - start
    history = result.history
    return {"input": name, "n": packing.n, "d": packing.d, "backend": backend,
            "lps": int(result.iterations), "total": total,
            "solver_share": float(history["solver_time"].sum() / total), "phi": result.phi,
            "contacts": int(result.n_contacts), "isostaticity_gap": int(result.isostaticity_gap),
            "force_balance": float(result.force_balance),
            "min_gap": float(history["min_gap"][-1]), "converged": bool(result.converged)}


def line(run: dict) -> str:
    """A run as a line of the table."""
    return (f"{run['input']:<44} {run['n']:>6} {run['d']:>2} {run['backend']:>8} "
            f"{run['lps']:>4} {run['total']:>8.2f} {run['solver_share']:>6.1%} "
            f"{run['phi']:>11.8f} {run['contacts']:>6} {run['isostaticity_gap']:>4} "
            f"{run['force_balance']:>8.1e} {run['min_gap']:>9.1e} "
            f"{'yes' if run['converged'] else 'NO':>4}")


def cached_ls_input(cache: Path | None, d: int, n: int, pressure: float, seed: int,
                    start: str, final_growth_rate: float | None) -> calippso.Packing:
    """`ls_input`, kept in `cache` (an .npz per input) when a cache folder is given."""
    if cache is None:
        return ls_input(d, n, pressure, seed, start, final_growth_rate)
    path = cache / f"ls_{start}_d{d}_n{n}_p{pressure:g}_end{final_growth_rate}_seed{seed}.npz"
    if not path.exists():
        cache.mkdir(parents=True, exist_ok=True)
        calippso.write(ls_input(d, n, pressure, seed, start, final_growth_rate), path)
    return calippso.read(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backends", nargs="+", default=["highs"])
    parser.add_argument("--ls", nargs="*", default=["3:1024"],
                        help="LS inputs to generate, as d:N (reduced pressure --pressure)")
    parser.add_argument("--pressure", type=float, default=1e5)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1],
                        help="seeds of the LS inputs (one row per seed)")
    parser.add_argument("--start", choices=["poisson", "fb"], default="poisson",
                        help="where the LS inputs begin: Poisson points (default) or an FB "
                             "packing (contraction rate 1e-3)")
    parser.add_argument("--final-growth-rate", type=float, default=None,
                        help="give the LS inputs a slow end: this growth rate from p = 1e3 on")
    parser.add_argument("--no-shared", action="store_true", help="skip ../shared/data inputs")
    parser.add_argument("--max-iters", type=int, default=500)
    parser.add_argument("--random", nargs="*", default=[],
                        help="random starts to generate, as d:N:phi (seed 1)")
    parser.add_argument("--precompress", type=float, default=None, metavar="P",
                        help="compress every input by LS to reduced pressure P before jam")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="further jam options, e.g. max_step=0.3 newton=False")
    parser.add_argument("--cache", type=Path, default=None,
                        help="folder that keeps the generated LS inputs for the next run")
    parser.add_argument("--json", type=Path, default=None, help="write the rows to this file")
    args = parser.parse_args()

    inputs = []
    if not args.no_shared and SHARED.is_dir():
        inputs += [(name, calippso.read(SHARED / name)) for name in SHARED_INPUTS]
    for spec in args.ls:
        d, n = (int(v) for v in spec.split(":"))
        label = "our LS" if args.start == "poisson" else "our FB -> LS"
        if args.final_growth_rate is not None:
            label += f" end {args.final_growth_rate:g}"
        inputs += [(f"{label} d={d} p={args.pressure:g} seed {seed}",
                    cached_ls_input(args.cache, d, n, args.pressure, seed, args.start,
                                    args.final_growth_rate))
                   for seed in args.seeds]
    for spec in args.random:
        d, n, phi = spec.split(":")
        inputs.append((f"random d={d} phi0={phi}",
                       random_sequential_addition(int(n), int(d), float(phi), seed=1)))
    options = parse_options(args.set)

    print(f"{'input':<44} {'N':>6} {'d':>2} {'backend':>8} {'LPs':>4} {'total s':>8} "
          f"{'solver':>6} {'phi_J':>11} {'N_c':>6} {'iso':>4} {'balance':>8} {'min gap':>9} "
          f"{'conv':>4}")
    runs = []
    for name, packing in inputs:
        for backend in args.backends:
            runs.append(row(name, packing, backend, args.max_iters, options, args.precompress))
            print(line(runs[-1]), flush=True)
    if len(runs) > 1:
        lps, seconds = sum(run["lps"] for run in runs), sum(run["total"] for run in runs)
        print(f"{len(runs)} runs: {lps} LPs, {seconds:.1f} s in all, "
              f"{seconds / len(runs):.1f} s per run")
    if args.json:
        args.json.write_text(json.dumps(runs, indent=1))


if __name__ == "__main__":
    main()
