"""Ensemble throughput against worker processes × threads per worker.

Runs the same ensemble (`calippso.ensemble.run`, local process pool) once per
(workers, threads) pair, each in a fresh output folder, and prints packings per minute.
Threads are those of `calippso.ensemble.limit_threads` (Numba, BLAS, MKL). The first pair
is run twice and its first run dropped, so that every timed run finds Numba's cache warm.

    python bench/ensemble_threads.py --pairs 2x1 2x2 1x2 --packings 8 --json threads.json
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time

from calippso import ensemble


def timed_run(spec: dict, packings: int, workers: int, threads: int) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        clock = time.perf_counter()
        rows = ensemble.run(spec, packings, seeds=1, out_dir=folder, workers=workers,
                            threads=threads)
        seconds = time.perf_counter() - clock
    done = sum(row["state"] == "done" for row in rows)
    return {"workers": workers, "threads": threads, "packings": packings, "done": done,
            "seconds": seconds, "per_minute": 60.0 * done / seconds}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", nargs="+", default=["2x1", "2x2", "1x2"],
                        help="WORKERSxTHREADS")
    parser.add_argument("--protocol", default="ls")
    parser.add_argument("--n", type=int, default=512)
    parser.add_argument("--d", type=int, default=3)
    parser.add_argument("--packings", type=int, default=8)
    parser.add_argument("--json", default="")
    args = parser.parse_args()
    spec = {"protocol": args.protocol, "n": args.n, "d": args.d}
    pairs = [tuple(int(k) for k in pair.split("x")) for pair in args.pairs]
    timed_run(spec, 2, *pairs[0])            # warm Numba's cache in the workers
    rows = []
    print(f"{'workers':>7} {'threads':>7} {'packings':>8} {'seconds':>8} {'per min':>8}")
    for workers, threads in pairs:
        row = timed_run(spec, args.packings, workers, threads)
        rows.append(row)
        print(f"{workers:>7} {threads:>7} {row['done']:>8} {row['seconds']:>8.1f} "
              f"{row['per_minute']:>8.2f}", flush=True)
    if args.json:
        with open(args.json, "w") as out:
            json.dump({"spec": spec, "rows": rows}, out, indent=1)


if __name__ == "__main__":
    main()
