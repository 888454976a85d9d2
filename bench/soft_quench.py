"""Benchmark of the soft-sphere quench (`generators.soft_quench`): density, pressure, cost.

Run with ``nice -n 10 python bench/soft_quench.py`` (N = 1024, 4096, 16384 in d = 3, one
seed each), or choose: ``--sizes 1024 4096 --seeds 1 2 3 --d 3 --json results.json``;
``--minimiser fire lbfgs`` runs each case with each minimiser; ``--jam`` then hands the
quench's network to ``calippso.jam(..., network_first="require")`` and reports its LPs,
time and φ_J (a refused network is reported as such). ``--kernels`` times instead each Numba
kernel of the quench with 1 and 2 threads, on the state after the first `--rungs`
minimisations of the ladder (one row per kernel and size: µs per call, speed-up).
Prints one row per run: the packing fraction after the shrink, the final soft pressure,
minimisations, steps (FIRE steps, L-BFGS force evaluations or Newton solves; with
``--minimiser newton`` the Newton solves among them), the steps and the wall time of the
slowest minimisation over the median of the others, wall and CPU seconds (all threads), and the
isostaticity gap N_c − (d (N_s − 1) + 1) of the overlap network handed to `calippso.jam`.
The JSON file holds the same rows. The first run includes Numba compilation unless the
on-disk cache is warm.
"""

from __future__ import annotations

import argparse
import importlib
import json
import time
from pathlib import Path

import numba
import numpy as np

import generators
from generators import _fire, _lbfgs
from generators import diameters as dist
from generators.cells import verlet_lists
from generators.initial import poisson

#: Wall time spent timing each kernel at each thread count (s), after one warm-up call.
KERNEL_SECONDS = 1.0


def slowest_over_median(steps: np.ndarray) -> float:
    """Steps of the slowest minimisation ÷ the median of the others (per rung of the ladder;
    the last rung's tightening rounds count with it)."""
    if steps.size < 2:
        return float("nan")
    slowest = int(np.argmax(steps))
    return float(steps[slowest] / np.median(np.delete(steps, slowest)))


def rung_times(call):
    """`call()` with the wall time of every minimisation recorded: its result and the seconds
    spent at each pressure of the ladder (its tightening rounds included), in order."""
    quench = importlib.import_module("generators.soft_quench")
    real = quench._SoftSpheres.minimise
    spent: dict[float, float] = {}

    def timed(system, pressure, *args, **kwargs):
        clock = time.perf_counter()
        try:
            return real(system, pressure, *args, **kwargs)
        finally:
            spent[pressure] = spent.get(pressure, 0.0) + time.perf_counter() - clock

    quench._SoftSpheres.minimise = timed
    try:
        result = call()
    finally:
        quench._SoftSpheres.minimise = real
    return result, np.array(list(spent.values()))


def jam_row(quench) -> dict:
    """`calippso.jam` on the quench's packing with its network (network first required)."""
    import calippso

    clock = time.perf_counter()
    try:
        result = calippso.jam(quench.packing, network=quench.contacts,
                              network_first="require")
    except calippso.JammingError as error:
        return {"jam_s": time.perf_counter() - clock, "jam_error": str(error)}
    return {"jam_s": time.perf_counter() - clock, "lps": result.iterations,
            "phi_j": result.phi, "isostatic": bool(result.isostatic)}


def run(n: int, d: int, seed: int, target_pressure: float | None, minimiser: str,
        jam: bool, save: Path | None = None) -> dict:
    """One quench of N monodisperse spheres (bidisperse 1:1.4 in d = 2); its table row. With
    `save`, the packing and its network go to ``save/quench_d{d}_n{n}_p{target_pressure:g}
    _seed{seed}.npz``, the name under which ``bench/scale.py --generator quench --cache save``
    reads it back instead of quenching (and `calippso.read` reads it)."""
    sizes = dist.bidisperse(n, 1.4, 0.5, seed) if d == 2 else dist.monodisperse(n)
    if target_pressure is None:
        target_pressure = generators.default_target_pressure(n, d)
    wall, cpu = time.perf_counter(), time.process_time()
    result, seconds = rung_times(lambda: generators.soft_quench(
        sizes, d, seed=seed, target_pressure=target_pressure, minimiser=minimiser))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    if save is not None:
        save.mkdir(parents=True, exist_ok=True)
        packing = result.packing
        np.savez(save / f"quench_d{d}_n{n}_p{target_pressure:g}_seed{seed}.npz",
                 positions=packing.positions, diameters=packing.diameters, box=packing.box,
                 contacts=result.contacts)
    extra = result.extra
    per_rung = np.diff(np.concatenate([[0], result.history["time"]]))
    row = {"n": n, "d": d, "seed": seed, "minimiser": extra["minimiser"],
           "phi": result.packing.phi,
           "pressure": extra["pressure"], "minimisations": extra["minimisations"],
           "steps": extra["fire_steps"], "newton_solves": extra["newton_solves"],
           "steps_per_rung": per_rung.tolist(),
           "slowest_over_median": slowest_over_median(per_rung),
           "seconds_per_rung": seconds.tolist(),
           "slowest_over_median_s": slowest_over_median(seconds),
           "rebuilds": extra["rebuilds"], "wall_s": wall, "cpu_s": cpu,
           "isostaticity_gap": extra["isostaticity_gap"], "stable": extra["stable"],
           "max_overlap": extra["max_overlap"], "status": result.status}
    return {**row, **(jam_row(result) if jam else {})}


def per_call(call, seconds: float = KERNEL_SECONDS) -> float:
    """Mean wall time of `call()` in µs, repeated for about `seconds`."""
    call()
    calls, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        call()
        calls += 1
    return (time.perf_counter() - start) / calls * 1e6


def kernel_rows(n: int, d: int, seed: int, rungs: int) -> list[dict]:
    """µs per call of each quench kernel with 1 and 2 threads, at the state after `rungs`
    minimisations (FIRE) of the ladder of the default quench."""
    quench = importlib.import_module("generators.soft_quench")
    sizes = dist.monodisperse(n)
    typical = quench.phi_estimate(d)
    start = poisson(sizes, d, phi=quench.PHI_START_FACTOR * typical, seed=seed)
    system = quench._SoftSpheres(start.positions, sizes, start.box, 0.2)
    for pressure in quench.pressure_ladder(quench.FIRST_PRESSURE, quench.TARGET_AIM * 1e-7)[:rungs]:
        system.minimise(pressure, quench.INTERMEDIATE_TOLERANCE, 10**7)
    system.rebuild()
    x, s, box, lists = system.x, system.s, system.box, system.lists
    f, v, y = np.zeros_like(x), np.zeros_like(x), x.copy()
    partial = _fire.work_array(n)
    pair_force = np.empty((lists[1].shape[0], d))
    rng = np.random.default_rng(seed)
    memory_x = rng.random((2, _lbfgs.HISTORY, x.size))
    memory_u = rng.random((4, _lbfgs.HISTORY))
    radii = system.scale * s
    periodic = system.periodic             # every axis periodic: no wall or cylinder terms
    csr = verlet_lists(x, box, radii, system.skin, periodic)
    kernels = {
        "harmonic_forces": lambda: _fire.harmonic_forces(x, v, s, system.scale, box, *lists,
                                                         pair_force, f, partial, periodic,
                                                         system.circle),
        "fire _move": lambda: _fire._move(y, v, f, x, 1e-9, 0.9, 0.0, False),
        "lbfgs _direction": lambda: _lbfgs._direction(f, 0.0, memory_x, memory_u,
                                                      _lbfgs.HISTORY, 0, v),
        "lbfgs _slope": lambda: _lbfgs._slope(f, 0.0, v, 0.0),
        "lbfgs _place": lambda: _lbfgs._place(y, x, v, 1e-9, x),
        "cell_order": lambda: _fire.cell_order(x, box, radii.max() + system.skin),
        "verlet_lists": lambda: verlet_lists(x, box, radii, system.skin, periodic),
        "pair_lists": lambda: _fire.pair_lists(*csr),
    }
    threads = numba.get_num_threads()
    rows = []
    try:
        for name, call in kernels.items():
            times = []
            for count in (1, 2):
                numba.set_num_threads(min(count, threads))
                times.append(per_call(call))
            rows.append({"n": n, "d": d, "kernel": name, "pairs": int(lists[1].shape[0]),
                         "skin": system.skin, "us_1": times[0], "us_2": times[1],
                         "speedup": times[0] / times[1]})
    finally:
        numba.set_num_threads(threads)
    return rows


def format_row(row: dict) -> str:
    line = (f"{row['n']:>6} {row['d']:>2} {row['seed']:>4} {row['minimiser']:>6} "
            f"{row['phi']:>8.5f} {row['pressure']:>8.2e} {row['minimisations']:>4} "
            f"{row['steps']:>9} {row['newton_solves']:>6} {row['slowest_over_median']:>6.1f} "
            f"{row['slowest_over_median_s']:>6.1f} {row['wall_s']:>7.1f} "
            f"{row['cpu_s']:>7.1f} {row['isostaticity_gap']:>+7d}")
    if "jam_error" in row:
        return line + f"  jam refused after {row['jam_s']:.1f} s: {row['jam_error']}"
    if "jam_s" in row:
        line += (f" {row['jam_s']:>6.1f} {row['lps']:>4} {row['phi_j']:>8.5f} "
                 f"{row['wall_s'] + row['jam_s']:>7.1f}")
    return line


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 4096, 16384])
    parser.add_argument("--d", type=int, default=3)
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--target-pressure", type=float, default=None,
                        help="default: generators.default_target_pressure(N, d)")
    parser.add_argument("--minimiser", nargs="+", default=["auto"],
                        choices=["auto", "fire", "lbfgs", "newton"],
                        help="run each case with each of these")
    parser.add_argument("--jam", action="store_true",
                        help="jam each result with its network (network_first='require')")
    parser.add_argument("--kernels", action="store_true",
                        help="time each kernel with 1 and 2 threads instead of quenching")
    parser.add_argument("--rungs", type=int, default=3,
                        help="with --kernels: minimisations before the timing")
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    parser.add_argument("--save", type=Path, default=None,
                        help="keep each quench's packing and network in this folder (in a "
                             "subfolder per minimiser when --minimiser names several)")
    args = parser.parse_args()

    if args.kernels:
        print(f"{'N':>6} {'d':>2} {'kernel':<18} {'pairs':>8} {'1 thread µs':>12} "
              f"{'2 threads µs':>13} {'speed-up':>8}")
        rows = []
        for n in args.sizes:
            for row in kernel_rows(n, args.d, args.seeds[0], args.rungs):
                rows.append(row)
                print(f"{n:>6} {args.d:>2} {row['kernel']:<18} {row['pairs']:>8} "
                      f"{row['us_1']:>12.1f} {row['us_2']:>13.1f} {row['speedup']:>8.2f}",
                      flush=True)
        if args.json is not None:
            args.json.write_text(json.dumps(rows, indent=1))
        return

    header = (f"{'N':>6} {'d':>2} {'seed':>4} {'method':>6} {'phi':>8} {'p':>8} {'min':>4} "
              f"{'steps':>9} {'solves':>6} {'max/md':>6} {'t/md':>6} {'wall s':>7} {'CPU s':>7} "
              f"{'iso gap':>7}")
    print(header + (f" {'jam s':>6} {'LPs':>4} {'phi_J':>8} {'both s':>7}" if args.jam
                    else ""))
    rows = []
    for n in args.sizes:
        for seed in args.seeds:
            for minimiser in args.minimiser:
                folder = args.save
                if folder is not None and len(args.minimiser) > 1:
                    folder = folder / minimiser
                rows.append(run(n, args.d, seed, args.target_pressure, minimiser, args.jam,
                                folder))
                print(format_row(rows[-1]), flush=True)
                if args.json is not None:
                    args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
