"""An ensemble of independent packings on local processes (or a Dask cluster).

Run time, once Numba has compiled the generators: about 20 s of CPU time, shared out over
the cores (--tiny: 5 s).

Each packing is written as soon as it is jammed; summary.csv gets one row per packing;
running the script again skips the packings already done.

    python examples/ensemble.py                          # 8 packings, N = 256, d = 3
    python examples/ensemble.py --tiny --out /tmp/ens    # 2 packings, N = 32
    python examples/ensemble.py --scheduler tcp://host:8786
"""

import argparse
from pathlib import Path

from calippso import ensemble


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--packings", type=int, default=8)
    parser.add_argument("--n", type=int, default=256, help="spheres per packing")
    parser.add_argument("--tiny", action="store_true", help="2 packings of N = 32")
    parser.add_argument("--out", type=Path, default=Path("ensemble"), help="output folder")
    parser.add_argument(
        "--scheduler", help="address of a Dask scheduler (default: local processes)"
    )
    args = parser.parse_args(argv)
    packings, n = (2, 32) if args.tiny else (args.packings, args.n)

    spec = ensemble.EnsembleSpec(protocol="ls", n=n, d=3, pressure=1e5)
    if args.scheduler:
        rows = ensemble.run_on_scheduler(
            spec, packings, address=args.scheduler, seeds=1, out_dir=args.out
        )
    else:
        rows = ensemble.run(spec, packings, seeds=1, out_dir=args.out, workers=2)
    for row in rows:
        if row["state"] == "done":
            print(
                f"seed {row['seed']}: phi_J = {row['phi']:.6f}, {row['n_contacts']} contacts, "
                f"isostatic = {row['isostatic']}"
            )
        else:
            print(f"seed {row['seed']}: failed ({row['error']})")
    print(f"summary -> {args.out / ensemble.SUMMARY}")


if __name__ == "__main__":  # needed: the worker processes import this file
    main()
