"""Jam packings in every container over many seeds, and count how each run ended.

For each protocol (the soft quench, or LS to a reduced pressure) and container (flat walls
in x, in x and y, a cylinder), makes N = 1000 (by default) packings in d = 3, jams each
with `calippso.jam`, and prints one row per (protocol, container): how many were certified
(converged), how many ended NOT_RIGID, how many otherwise, and the LPs. The per-seed rows
(stop reason, LPs, isostaticity gap, touching pairs outside the network, wall time) go to
the JSON file, which is written after every run: an interrupted scan resumes where it
stopped.

    python bench/container_scan.py --seeds 1 2 3 4 5 6 7 8 9 10 --json scan.json
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import calippso
from calippso import Boundaries
from calippso.atomic import atomic_path

CONTAINERS = {"walls:x": ("walls", "x"), "walls:x,y": ("walls", "x,y"),
              "cylinder:x,y": ("cylinder", "x,y")}


def make(protocol: str, container: str, n: int, d: int, seed: int, pressure: float):
    """The start (packing, network hint or None) and the seconds it took."""
    import generators

    kind, axes = CONTAINERS[container]
    boundaries = getattr(Boundaries, kind)(d, axes.split(","))
    sizes = generators.diameters.monodisperse(n)
    clock = time.perf_counter()
    if protocol == "quench":
        made = generators.soft_quench(sizes, d, seed=seed, boundaries=boundaries)
        hint = made.contacts
    else:
        made = generators.lubachevsky_stillinger(sizes, d=d, target_pressure=pressure,
                                                 seed=seed, boundaries=boundaries)
        hint = None
    return made.packing, hint, time.perf_counter() - clock


def cached(cache: str, protocol: str, container: str, n: int, d: int, seed: int,
           pressure: float):
    """`make`, kept in the folder `cache` (none: made every time)."""
    if not cache:
        return make(protocol, container, n, d, seed, pressure)
    name = f"{protocol}_{container.replace(':', '_').replace(',', '')}_d{d}_n{n}_s{seed}"
    if protocol == "ls":
        name += f"_p{pressure:g}"
    path = Path(cache) / f"{name}.npz"
    if path.exists():
        with np.load(path) as stored:
            hint = stored["hint"] if "hint" in stored.files else None
            made = float(stored["make_s"])
        return calippso.read(path), hint, made
    packing, hint, made = make(protocol, container, n, d, seed, pressure)
    extra = {} if hint is None else {"hint": hint}
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, positions=packing.positions, diameters=packing.diameters, box=packing.box,
             boundaries=str(packing.boundaries), make_s=made, **extra)
    return packing, hint, made


def run_one(protocol: str, container: str, n: int, d: int, seed: int, pressure: float,
            cache: str = "") -> dict:
    packing, hint, made = cached(cache, protocol, container, n, d, seed, pressure)
    clock = time.perf_counter()
    try:
        result = calippso.jam(packing, network=hint)
    except Exception as error:     # counted as "other", with the error kept
        return {"protocol": protocol, "container": container, "n": n, "d": d, "seed": seed,
                "make_s": made, "jam_s": time.perf_counter() - clock, "lps": 0,
                "converged": False, "stop_reason": "error", "isostaticity_gap": 0,
                "touching": 0, "phi": float("nan"), "floppy_note": False,
                "error": f"{type(error).__name__}: {error}"}
    return {
        "protocol": protocol, "container": container, "n": n, "d": d, "seed": seed,
        "make_s": made, "jam_s": time.perf_counter() - clock,
        "lps": int(result.iterations), "converged": bool(result.converged),
        "stop_reason": result.stop_reason.value if result.stop_reason else None,
        "isostaticity_gap": int(result.isostaticity_gap),
        "touching": len(result.touching), "phi": float(result.phi),
        "floppy_note": any("floppy" in note for note in result.notes),
    }


def summary(rows: list[dict]) -> list[dict]:
    """One row per (protocol, container): certified, NOT_RIGID, other, LPs."""
    table = []
    for key in sorted({(r["protocol"], r["container"]) for r in rows}):
        group = [r for r in rows if (r["protocol"], r["container"]) == key]
        lps = np.array([r["lps"] for r in group])
        table.append({
            "protocol": key[0], "container": key[1], "runs": len(group),
            "certified": sum(r["converged"] for r in group),
            "not_rigid": sum(r["stop_reason"] == "not_rigid" for r in group),
            "other": sum(not r["converged"] and r["stop_reason"] != "not_rigid"
                         for r in group),
            "lps_median": float(np.median(lps)), "lps_max": int(lps.max()),
            "touching_runs": sum(r["touching"] > 0 for r in group),
            "jam_s_median": float(np.median([r["jam_s"] for r in group])),
        })
    return table


def print_summary(table: list[dict]) -> None:
    print(f"{'protocol':>8} {'container':>13} {'runs':>4} {'certified':>9} {'NOT_RIGID':>9} "
          f"{'other':>5} {'LPs med':>7} {'LPs max':>7} {'touching':>8} {'jam s med':>9}")
    for row in table:
        print(f"{row['protocol']:>8} {row['container']:>13} {row['runs']:>4} "
              f"{row['certified']:>9} {row['not_rigid']:>9} {row['other']:>5} "
              f"{row['lps_median']:>7.0f} {row['lps_max']:>7} {row['touching_runs']:>8} "
              f"{row['jam_s_median']:>9.1f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocols", nargs="+", default=["quench", "ls"],
                        choices=["quench", "ls"])
    parser.add_argument("--containers", nargs="+", default=list(CONTAINERS),
                        choices=list(CONTAINERS))
    parser.add_argument("--seeds", nargs="+", type=int, default=list(range(1, 11)))
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--d", type=int, default=3)
    parser.add_argument("--pressure", type=float, default=1e5, help="LS reduced pressure")
    parser.add_argument("--json", default="", help="rows written (and resumed) here")
    parser.add_argument("--cache", default="", help="folder where the starts are kept")
    args = parser.parse_args()
    rows: list[dict] = []
    if args.json and os.path.exists(args.json):
        with open(args.json) as stored:
            rows = json.load(stored)["runs"]
    done = {(r["protocol"], r["container"], r["seed"]) for r in rows}
    for protocol in args.protocols:
        for container in args.containers:
            for seed in args.seeds:
                if (protocol, container, seed) in done:
                    continue
                row = run_one(protocol, container, args.n, args.d, seed, args.pressure,
                              args.cache)
                rows.append(row)
                print(json.dumps(row), flush=True)
                if args.json:
                    with atomic_path(Path(args.json)) as temporary:
                        temporary.write_text(json.dumps(
                            {"runs": rows, "summary": summary(rows)}, indent=1))
    print_summary(summary(rows))


if __name__ == "__main__":
    main()
