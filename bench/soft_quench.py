"""Benchmark of the soft-sphere quench (`generators.soft_quench`): density, pressure, cost.

Run with ``nice -n 10 python bench/soft_quench.py`` (N = 1024, 4096, 16384 in d = 3, one
seed each), or choose: ``--sizes 1024 4096 --seeds 1 2 3 --d 3 --json results.json``.
Prints one row per run: the packing fraction after the shrink, the final soft pressure,
minimisations, FIRE steps, wall and CPU seconds (all threads), and the isostaticity gap
N_c − (d (N_s − 1) + 1) of the overlap network handed to `calippso.jam`. The JSON file holds
the same rows. The first run includes Numba compilation unless the on-disk cache is warm.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import generators
from generators import diameters as dist


def run(n: int, d: int, seed: int, target_pressure: float) -> dict:
    """One quench of N monodisperse spheres (bidisperse 1:1.4 in d = 2); its table row."""
    sizes = dist.bidisperse(n, 1.4, 0.5, seed) if d == 2 else dist.monodisperse(n)
    wall, cpu = time.perf_counter(), time.process_time()
    result = generators.soft_quench(sizes, d, seed=seed, target_pressure=target_pressure)
    extra = result.extra
    return {"n": n, "d": d, "seed": seed, "phi": result.packing.phi,
            "pressure": extra["pressure"], "minimisations": extra["minimisations"],
            "fire_steps": extra["fire_steps"], "wall_s": time.perf_counter() - wall,
            "cpu_s": time.process_time() - cpu,
            "isostaticity_gap": extra["isostaticity_gap"], "stable": extra["stable"],
            "max_overlap": extra["max_overlap"], "status": result.status}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 4096, 16384])
    parser.add_argument("--d", type=int, default=3)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--target-pressure", type=float, default=1e-7)
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    args = parser.parse_args()

    print(f"{'N':>6} {'d':>2} {'seed':>4} {'phi':>8} {'p':>8} {'min':>4} {'FIRE steps':>10} "
          f"{'wall s':>7} {'CPU s':>7} {'iso gap':>7}")
    rows = []
    for n in args.sizes:
        for seed in args.seeds:
            row = run(n, args.d, seed, args.target_pressure)
            rows.append(row)
            print(f"{n:>6} {args.d:>2} {seed:>4} {row['phi']:>8.5f} {row['pressure']:>8.2e} "
                  f"{row['minimisations']:>4} {row['fire_steps']:>10} {row['wall_s']:>7.1f} "
                  f"{row['cpu_s']:>7.1f} {row['isostaticity_gap']:>+7d}", flush=True)
            if args.json is not None:
                args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
