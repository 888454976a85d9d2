"""The two LP engines on the same inputs: vertex LPs (``crossover="on"``, the default)
against interior LPs read by complementarity (``crossover="off"``).

Inputs: the near-jammed and compressed files of ../shared/data and LS packings made by
`bench/jam.py`'s `ls_input` (d:N, reduced pressure --pressure, --seeds). Every input is
jammed by both engines with the LP loop from the start (``network_first="off"``, so that
the engines, not network first, decide). Run from the repository root:

    python bench/engines.py                                   # shared files + LS 3:1024 seeds 1-3
    python bench/engines.py --no-shared --ls 3:2048 --seeds 1 --json engines.json
    python bench/engines.py --ls 2:1024 5:1024 --set pivots=off

Columns per engine: stop reason, LPs, wall time (s), φ_J, contacts; then |Δφ_J| between the
engines and whether both are certified.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import calippso
from jam import SHARED, cached_ls_input, parse_options

#: The shared files compared (the fourth, a loose FB state, takes hundreds of LPs).
SHARED_FILES = ["skoge_donev_N1000_d3_p1e12.dat", "mono_N1000_fba1e-3_then_ls1e-2_seed11",
                "lognormal0.2_N1000_fba1e-3_then_ls1e-2_seed13"]
ENGINES = {"vertex": {"crossover": "on"}, "interior": {"crossover": "off"}}


def run(packing: calippso.Packing, options: dict) -> dict:
    """One `jam` of `packing` with `options`: the figures of one engine's columns."""
    began = time.perf_counter()
    result = calippso.jam(packing, network_first="off", **options)
    return {"reason": result.stop_reason.value, "lps": int(result.iterations),
            "seconds": time.perf_counter() - began, "phi": result.phi,
            "contacts": int(result.n_contacts), "certified": bool(result.converged
                                                                  and result.isostatic)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ls", nargs="*", default=["3:1024"], help="LS inputs, as d:N")
    parser.add_argument("--pressure", type=float, default=1e5)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--no-shared", action="store_true")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="further jam options for both engines")
    parser.add_argument("--cache", type=Path, default=None, help="folder for the LS inputs")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    inputs = []
    if not args.no_shared and SHARED.is_dir():
        inputs += [(name, calippso.read(SHARED / name)) for name in SHARED_FILES]
    for spec in args.ls:
        d, n = (int(v) for v in spec.split(":"))
        inputs += [(f"LS d={d} N={n} p={args.pressure:g} seed {seed}",
                    cached_ls_input(args.cache, d, n, args.pressure, seed, "poisson", None))
                   for seed in args.seeds]
    extra = parse_options(args.set)
    print(f"{'input':<44} " + " ".join(f"{name + ' stop':>17} {'LPs':>4} {'s':>7} "
                                       f"{'phi_J':>13} {'N_c':>6}" for name in ENGINES)
          + f" {'|dphi|':>8} both")
    rows = []
    for name, packing in inputs:
        row = {"input": name, **{engine: run(packing, {**options, **extra})
                                 for engine, options in ENGINES.items()}}
        row["dphi"] = abs(row["vertex"]["phi"] - row["interior"]["phi"])
        rows.append(row)
        print(f"{name:<44} " + " ".join(
            f"{row[e]['reason']:>17} {row[e]['lps']:>4} {row[e]['seconds']:>7.1f} "
            f"{row[e]['phi']:>13.10f} {row[e]['contacts']:>6}" for e in ENGINES)
            + f" {row['dphi']:>8.1e} "
            + ("yes" if row["vertex"]["certified"] and row["interior"]["certified"] else "NO"),
            flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
