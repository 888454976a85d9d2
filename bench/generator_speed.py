"""Benchmark of the Numba generators: LS collisions per second, FB wall time, compile time.

Run with ``nice -n 10 python bench/generator_speed.py`` (add ``--quick`` to skip N = 10⁴ LS,
``--json PATH`` to write the figures to a file). CPU seconds (``time.process_time``, one core)
are the figure of merit; wall seconds are shown as well since the machine may be shared.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import generators
from generators import diameters as dist

#: Particles of the FB runs.
FB_SIZE = 10_000

COMPILE_PROBE = """
import time
t = time.perf_counter()
import generators
generators.lubachevsky_stillinger(generators.diameters.monodisperse(64), d=3,
                                  target_pressure=1e2, seed=0)
generators.force_biased(generators.diameters.monodisperse(64), 3, seed=0)
print(time.perf_counter() - t)
"""


def first_call_seconds(cache_dir: str) -> float:
    """Seconds of a tiny LS + FB run in a fresh interpreter with the given Numba cache."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    out = subprocess.run([sys.executable, "-c", COMPILE_PROBE], env=env, check=True,
                         capture_output=True, text=True)
    return float(out.stdout.strip())


def timed(call):
    """The result of `call()` with its wall and CPU seconds."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = call()
    return result, time.perf_counter() - wall, time.process_time() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="skip LS at N = 10^4")
    parser.add_argument("--json", type=Path, default=None,
                        help="write the compile times and the LS and FB rows here")
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as cache:
        cold = first_call_seconds(cache)
        warm = first_call_seconds(cache)
    print(f"first call (compile + run, empty cache): {cold:.1f} s; "
          f"with the on-disk cache: {warm:.1f} s\n")
    figures = {"compile": {"empty_cache": cold, "on_disk_cache": warm}, "ls": [], "fb": []}

    print("LS from Poisson points to p = 1e5, growth rate 1e-2, kT = 1")
    print(f"{'d':>2} {'N':>6} {'collisions':>11} {'wall s':>7} {'CPU s':>7} "
          f"{'coll/CPU-s':>11} {'phi':>8} {'p':>9}")
    cases = [(3, 1000), (3, 10000), (2, 1000), (4, 1000), (5, 1000)]
    for d, n in cases:
        if args.quick and n > 1000:
            continue
        diameters = dist.bidisperse(n, 1.4, 0.5) if d == 2 else dist.monodisperse(n)
        result, wall, cpu = timed(lambda: generators.lubachevsky_stillinger(
            diameters, d=d, target_pressure=1e5, seed=1))
        print(f"{d:>2} {n:>6} {result.steps:>11} {wall:>7.1f} {cpu:>7.1f} "
              f"{result.steps / cpu:>11.3g} {result.packing.phi:>8.5f} "
              f"{result.reduced_pressure:>9.3g}")
        figures["ls"].append({"d": d, "n": n, "collisions": int(result.steps),
                              "wall_time": wall, "cpu_time": cpu,
                              "collisions_per_cpu_second": result.steps / cpu,
                              "phi": result.packing.phi,
                              "reduced_pressure": float(result.reduced_pressure)})

    print("\nFB, d = 3, monodisperse, N = 10^4")
    print(f"{'tau':>7} {'steps':>6} {'wall s':>7} {'CPU s':>7} {'phi':>8}")
    for tau in (1e-3, 1e-4):
        result, wall, cpu = timed(lambda: generators.force_biased(
            dist.monodisperse(FB_SIZE), 3, contraction_rate=tau, seed=1))
        print(f"{tau:>7.0e} {result.steps:>6} {wall:>7.1f} {cpu:>7.1f} "
              f"{result.packing.phi:>8.5f}")
        figures["fb"].append({"d": 3, "n": FB_SIZE, "contraction_rate": tau,
                              "steps": int(result.steps), "wall_time": wall,
                              "cpu_time": cpu, "phi": result.packing.phi})
    if args.json:
        args.json.write_text(json.dumps(figures, indent=1))


if __name__ == "__main__":
    main()
