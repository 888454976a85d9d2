"""Benchmark of the network-first stage of `calippso.jam` on near-jammed inputs.

A near-jammed input is a jammed packing with every diameter shrunk by a factor 1 − 2e-7 and
every position moved by 1e-9 mean diameters (Gaussian, seeded): its jamming point and contact
network are those of the jammed packing. Each input is jammed twice, with
``network_first="auto"`` (the default: the input's own network, certified by Newton, no LP)
and ``network_first="off"`` (the LP loop), and the table compares them with the packing the
input was made from.

    python bench/network_first.py --make 3:1024:1 4:1024:1 5:1024:1 --cache bench-cache
    python bench/network_first.py jammed.npz other.npz --json network_first.json

`--make d:N:seed` builds the jammed packing (LS to reduced pressure 1e5, then `jam`) once and
keeps it in `--cache`. Columns: d, N, mode, LPs, wall time of `jam` (s), Newton
factorisations, |φ_J − φ_J(source)|, same contacts, largest force difference, force balance.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import calippso

#: Relative shrink of every diameter, and size of the random displacements (mean diameters),
#: that make a near-jammed input from a jammed packing.
SHRINK = 2e-7
MOVE = 1e-9


def near_jammed(packing: calippso.Packing, seed: int = 0) -> calippso.Packing:
    """The jammed `packing` shrunk by `SHRINK` and moved by `MOVE` (seeded Gaussian)."""
    rng = np.random.default_rng(seed)
    moved = packing.positions + MOVE * packing.mean_diameter * rng.standard_normal(
        packing.positions.shape)
    return calippso.Packing(moved, packing.diameters * (1.0 - SHRINK), packing.box)


def made(spec: str, cache: Path) -> Path:
    """The jammed packing of `d:N:seed` (LS to p = 1e5, then jam), cached as an .npz file."""
    import generators

    d, n, seed = (int(part) for part in spec.split(":"))
    path = cache / f"jammed_d{d}_n{n}_seed{seed}.npz"
    if not path.exists():
        sizes = generators.diameters.monodisperse(n)
        start = generators.lubachevsky_stillinger(sizes, d=d, target_pressure=1e5,
                                                  seed=seed).packing
        calippso.jam(start).save(path)
    return path


def compare(source: calippso.JammingResult, mode: str) -> dict:
    """Jam the near-jammed input of `source` with `network_first=mode`; one table row."""
    start = near_jammed(source.packing)
    began = time.perf_counter()
    result = calippso.jam(start, network_first=mode)
    wall = time.perf_counter() - began
    same = np.array_equal(result.contacts, source.contacts)
    newton = result.history[result.history["stage"] == "newton"]
    return {
        "d": source.d, "n": source.packing.n, "mode": mode, "lps": int(result.iterations),
        "wall_time": wall,
        "newton_time": float(newton["solver_time"].sum()),
        "phi_difference": abs(result.phi - source.phi),
        "same_contacts": bool(same),
        "force_difference": (float(np.abs(result.forces - source.forces).max())
                             if same else float("nan")),
        "force_balance": float(result.force_balance),
        "isostatic": bool(result.isostatic),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="*", type=Path, help="jammed .npz results")
    parser.add_argument("--make", nargs="*", default=[], metavar="d:N:seed",
                        help="jammed packings to build (LS p = 1e5, then jam) and cache")
    parser.add_argument("--cache", type=Path, default=Path("bench-cache"))
    parser.add_argument("--modes", nargs="+", default=["auto", "off"])
    parser.add_argument("--json", type=Path, help="write the rows to this JSON file")
    args = parser.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    paths = list(args.results) + [made(spec, args.cache) for spec in args.make]
    print(f"{'d':>2} {'N':>6} {'mode':>5} {'LPs':>4} {'wall s':>7} {'Newton s':>8} "
          f"{'|dphi|':>8} {'contacts':>8} {'|df|':>8} {'balance':>8}")
    rows = []
    if paths:   # one untimed run, so that the first row does not pay the imports
        compare(calippso.load_result(paths[0]), args.modes[0])
    for path in paths:
        source = calippso.load_result(path)
        for mode in args.modes:
            row = compare(source, mode)
            rows.append({"input": str(path), **row})
            print(f"{row['d']:2d} {row['n']:6d} {mode:>5} {row['lps']:4d} "
                  f"{row['wall_time']:7.2f} {row['newton_time']:8.2f} "
                  f"{row['phi_difference']:8.1e} {'same' if row['same_contacts'] else 'differ':>8} "
                  f"{row['force_difference']:8.1e} {row['force_balance']:8.1e}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
