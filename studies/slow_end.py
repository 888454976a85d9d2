"""LS with and without a slow end: how close the LS state is to jamming, what `jam` then costs,
and the exponents of the jammed packings.

For every growth rate of the end (``none``: 1e-2 throughout) and every seed it makes an LS
packing (monodisperse, growth rate 1e-2, then the final rate from p = 1e3 on, up to
--pressure), jams it with the default `calippso.jam` settings and prints one row per run:
LS wall time, φ of the LS state, the free-volume estimate φ (1 + d/p) of its jamming density
when the run passed p = 1e4 and at its end, φ_J/φ − 1 against the free-volume value d/p, the
pairs of the LS state with h < 1e-5 against the contacts after jamming, LPs, jam wall time,
and the median displacement of the particles from LS state to jammed packing (common
translation removed, in mean diameters). Then, per final rate, the exponents of the pooled
packings (`calippso.analysis.analyze`, default windows, 1000 resamples of whole packings).
Run from the repository root:

    python studies/slow_end.py --rates none 1e-3 1e-4 --seeds 2 3 4 --keep /tmp/slow-end
    python studies/slow_end.py --rates 1e-3 --seeds $(seq 2 21) --keep /tmp/slow-end

`--keep DIR` stores the LS states and the jammed packings and reads them back on the next
run (the wall times printed are then those of the stored runs).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import calippso
from calippso.analysis import analyze
from calippso.geometry.neighbors import NeighborSearch

SLOWDOWN_PRESSURE = 1e3


def ls_state(d: int, n: int, rate: float | None, pressure: float, seed: int,
             keep: Path | None) -> tuple[calippso.Packing, float, float, float]:
    """The LS packing, its measured reduced pressure, its wall time, and the free-volume
    estimate φ (1 + d/p) of the first window past p = 1e4."""
    path = keep / f"ls_d{d}_n{n}_end{rate}_p{pressure:g}_s{seed}.npz" if keep else None
    if path is not None and path.exists():
        with np.load(path) as data:
            packing = calippso.Packing(data["positions"], data["diameters"], data["box"])
            return (packing, float(data["pressure"]), float(data["wall_time"]),
                    float(data["estimate_1e4"]))
    import generators

    run = generators.lubachevsky_stillinger(
        generators.diameters.monodisperse(n), d=d, target_pressure=pressure, seed=seed,
        final_growth_rate=rate, slowdown_pressure=SLOWDOWN_PRESSURE)
    packing = run.packing
    past = np.flatnonzero(run.history["pressure"] >= 1e4)
    first = past[0] if past.size else -1
    estimate = float(run.history["phi"][first] * (1 + d / run.history["pressure"][first]))
    if path is not None:
        np.savez(path, positions=packing.positions, diameters=packing.diameters,
                 box=packing.box, pressure=run.reduced_pressure, wall_time=run.wall_time,
                 estimate_1e4=estimate)
    return packing, run.reduced_pressure, run.wall_time, estimate


def close_pairs(packing: calippso.Packing, below: float = 1e-5) -> int:
    """Pairs with gap h = |r|/σ − 1 < `below`."""
    search = NeighborSearch(packing.positions, packing.diameters, packing.box)
    pairs = search.pairs_within(1.01 * float(packing.diameters.max()))
    return int(np.count_nonzero(pairs.gaps < below))


def jammed(packing: calippso.Packing, name: str, keep: Path | None) -> calippso.JammingResult:
    """`calippso.jam` of the LS packing (read back from `keep` when stored there)."""
    path = keep / f"jam_{name}.npz" if keep else None
    if path is not None and path.exists():
        return calippso.load_result(path)
    result = calippso.jam(packing)
    if path is not None:
        result.save(path)
    return result


def median_move(start: calippso.Packing, result: calippso.JammingResult) -> float:
    """Median displacement from `start` to the jammed packing, common translation removed."""
    moved = result.packing.positions - start.positions
    moved -= start.box * np.round(moved / start.box)
    moved -= moved.mean(axis=0)
    return float(np.median(np.linalg.norm(moved, axis=1)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rates", nargs="+", default=["none", "1e-3", "1e-4"],
                        help="final growth rates ('none': 1e-2 throughout)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[2, 3, 4])
    parser.add_argument("--d", type=int, default=3)
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--pressure", type=float, default=1e7)
    parser.add_argument("--keep", type=Path, help="folder to store and reuse packings")
    args = parser.parse_args()
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)

    print(f"{'end rate':>8} {'seed':>4} {'LS s':>7} {'phi LS':>10} {'est. p=1e4':>10} "
          f"{'est. end':>10} {'(phi_J/phi-1)/(d/p)':>20} {'h<1e-5 | N_c':>13} {'LPs':>4} "
          f"{'jam s':>7} {'median move':>11}")
    pooled = {}
    for label in args.rates:
        rate = None if label == "none" else float(label)
        results = []
        for seed in args.seeds:
            packing, pressure, ls_seconds, estimate = ls_state(args.d, args.n, rate,
                                                               args.pressure, seed, args.keep)
            name = f"d{args.d}_n{args.n}_end{rate}_p{args.pressure:g}_s{seed}"
            result = jammed(packing, name, args.keep)
            excess = (result.phi / packing.phi - 1) / (args.d / pressure)
            closed = f"{close_pairs(packing)} | {result.n_contacts}"
            print(f"{label:>8} {seed:>4} {ls_seconds:>7.1f} {packing.phi:>10.7f} "
                  f"{estimate:>10.7f} {packing.phi * (1 + args.d / pressure):>10.7f} "
                  f"{excess:>20.3g} {closed:>13} {result.iterations:>4} {result.wall_time:>7.1f} "
                  f"{median_move(packing, result):>11.2e}", flush=True)
            results.append(result)
        pooled[label] = results
    for label, results in pooled.items():
        if len(results) < 2:
            continue
        analysis = analyze(results, n_bootstrap=1000, seed=0)
        print(f"end rate {label}, {len(results)} packings, phi_J "
              f"{np.mean(analysis.contacts.phi):.5f} +- {np.std(analysis.contacts.phi):.5f}")
        for key, e in analysis.exponents.items():
            print(f"  {key:<8} {e.value:.3f} [{e.interval[0]:.3f}, {e.interval[1]:.3f}] "
                  f"(reference {e.reference}, window [{e.fit.lower:.2g}, {e.fit.upper:.2g}], "
                  f"{e.fit.n_points} points)")


if __name__ == "__main__":
    main()
