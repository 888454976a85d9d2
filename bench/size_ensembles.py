"""Certified packings across sizes for the finite-size study of the critical exponents.

Each packing is the soft-sphere quench of monodisperse spheres (`generators.soft_quench`,
default options) handed to ``calippso.jam(q.packing, network=q.contacts)``; it is kept only
when certified: converged, isostatic, every force positive and the force balance at most
`MAX_FORCE_BALANCE`. Run with, e.g.::

    python bench/size_ensembles.py --out DIR --plan 1024:80 2048:40 4096:20 8192:10

which makes seeds 1–80 at N = 1024, seeds 1–40 at N = 2048, and so on, the sizes
interleaved in proportion to their counts (d = 3; ``--d 4`` for d = 4; ``--first-seed``
moves the seeds). The run resumes: a packing whose
file exists is skipped, and a quench interrupted midway continues from its checkpoint
(``state_<seed>.npz``, removed once the packing is written). Every packing is written
atomically as ``DIR/d<d>_n<N>/packing_<seed>.npz`` (the full `JammingResult`) with
``packing_<seed>.json`` beside it (seed, quench and jam seconds, certification); a packing
that fails certification gets ``packing_<seed>.failed.json`` instead and is skipped by later
runs unless ``--retry-failed``. Each packing (quench and jam) holds the lock file
``--lock FILE`` (a lock file of ``flock(1)``; none by default) for its whole run and
releases it before the next, so that other work on the machine interleaves; ``--max-minutes``
stops before starting a packing once that much wall time has passed.

Prints one row per packing made and, at the end, the count per size; ``--json FILE`` writes
every row of the folder (made now or before). Then ``calippso report DIR/d3_n*`` pools them.

``--estimate`` makes nothing: per size it fits γ, θ_e, θ_ℓ and θ on the packings made (the
defaults of `calippso.analysis`) and prints how many packings would bring the interval of γ
to ± `GAMMA_HALF_WIDTH` and that of θ_e to ± `THETA_E_HALF_WIDTH`
(`calippso.analysis.packings_needed`: the width falls as 1/√packings).

``--window-scan`` makes nothing either: per size it fits γ on the pooled gaps with the top of
the fit window moved from 1e-4 to 1e-1 (`calippso.analysis.window_scan`, maximum likelihood,
pure power law), the check that the fitted γ does not follow the window.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

#: Largest force balance (max |net force| / mean force) of a packing kept.
MAX_FORCE_BALANCE = 1e-12
#: Seconds between two checkpoint writes of a quench.
CHECKPOINT_EVERY = 30.0
#: Half-widths of the 95 % intervals the study aims at (issue targets).
GAMMA_HALF_WIDTH = 0.02
THETA_E_HALF_WIDTH = 0.04
#: Largest gap pooled for the window scan (above its largest window top, 1e-1).
SCAN_MAX_GAP = 0.5


@contextmanager
def cpu_lock(path: str | None):
    """Hold the exclusive `flock` on `path` (the lock of ``flock(1)``) inside the block."""
    if path is None:
        yield
        return
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def certification(result) -> dict:
    """Whether `result` is a certified jamming point, with the numbers that say so."""
    positive = bool(result.forces.size and np.all(result.forces > 0))
    balance = float(result.force_balance)
    return {"converged": bool(result.converged), "isostatic": bool(result.isostatic),
            "positive_forces": positive, "force_balance": balance,
            "certified": bool(result.converged and result.isostatic and positive
                              and balance <= MAX_FORCE_BALANCE)}


def write_json_atomic(data: dict, path: Path) -> None:
    """`data` as JSON in `path`, through a temporary file and a rename."""
    from calippso.atomic import atomic_path

    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(data, indent=1) + "\n")


def make_packing(n: int, d: int, seed: int, folder: Path, lock: str | None) -> dict:
    """Quench, jam and certify one packing; write it (or its failure) into `folder`."""
    import calippso
    import generators

    state = folder / f"state_{seed}.npz"
    with cpu_lock(lock):
        clock = time.perf_counter()
        quench = generators.soft_quench(generators.diameters.monodisperse(n), d, seed=seed,
                                        checkpoint=state, checkpoint_every=CHECKPOINT_EVERY)
        quench_s = time.perf_counter() - clock
        clock = time.perf_counter()
        try:
            result = calippso.jam(quench.packing, network=quench.contacts)
            error = None
        except calippso.JammingError as failure:
            result, error = None, str(failure)
        jam_s = time.perf_counter() - clock
    row = {"n": n, "d": d, "seed": seed, "quench_s": quench_s,
           "quench_wall_time_s": float(quench.wall_time), "jam_s": jam_s,
           "target_pressure": float(quench.extra["target_pressure"])}
    if result is not None:
        row.update(certification(result), phi=float(result.phi), lps=int(result.iterations))
    else:
        row.update(certified=False, error=error)
    if row["certified"]:
        result.save(folder / f"packing_{seed}.npz")
        write_json_atomic(row, folder / f"packing_{seed}.json")
    else:
        write_json_atomic(row, folder / f"packing_{seed}.failed.json")
    state.unlink(missing_ok=True)
    return row


def size_folders(out: Path, d: int):
    """(folder, packing files, results) of every size folder of `out` that holds packings,
    in increasing N."""
    import calippso

    for folder in sorted(out.glob(f"d{d}_n*"), key=lambda f: int(f.name.split("_n")[1])):
        files = sorted(folder.glob("packing_*.npz"))
        if files:
            yield folder, files, [calippso.load_result(f) for f in files]


def estimate(out: Path, d: int) -> list[dict]:
    """Per size folder: the exponents of its packings and the packings needed for the
    target intervals (printed as a table)."""
    from calippso.analysis import critical_exponents, packings_needed

    rows = []
    print("| N | packings | γ | θ_e | θ_ℓ | θ | packings for γ ± "
          f"{GAMMA_HALF_WIDTH:g} | for θ_e ± {THETA_E_HALF_WIDTH:g} |")
    print("|---|---|---|---|---|---|---|---|")
    for folder, files, results in size_folders(out, d):
        try:
            fitted = critical_exponents(results)
        except ValueError as error:
            print(f"| {folder.name} | {len(files)} | not fitted: {error} |")
            continue
        cells = {name: f"{e.value:.3f} [{e.interval[0]:.3f}, {e.interval[1]:.3f}]"
                 for name, e in fitted.items()}
        need = {"gamma": packings_needed(fitted["gamma"].interval, len(files),
                                         GAMMA_HALF_WIDTH),
                "theta_e": packings_needed(fitted["theta_e"].interval, len(files),
                                           THETA_E_HALF_WIDTH)}
        n = results[0].packing.n
        print(f"| {n} | {len(files)} | {cells['gamma']} | {cells['theta_e']} | "
              f"{cells['theta_l']} | {cells['theta']} | {need['gamma']} | {need['theta_e']} |",
              flush=True)
        rows.append({"n": n, "packings": len(files), "needed": need,
                     **{name: {"value": e.value, "interval": list(e.interval)}
                        for name, e in fitted.items()}})
    return rows


def window_scan_rows(out: Path, d: int) -> list[dict]:
    """Per size folder: γ of its pooled gaps against the top of the fit window (printed as a
    table, one column per top)."""
    from calippso.analysis import window_scan
    from calippso.analysis.gaps import pooled_gaps

    rows = []
    for _, files, results in size_folders(out, d):
        scan = window_scan("gamma", pooled_gaps(results, SCAN_MAX_GAP), largest=SCAN_MAX_GAP)
        if not rows:
            print("| N | packings | " + " | ".join(f"top {r['upper']:.1e}" for r in scan) + " |")
            print("|---|---|" + "---|" * len(scan))
        n = results[0].packing.n
        print(f"| {n} | {len(files)} | " + " | ".join(f"{r['power_law']:.3f}" for r in scan)
              + " |", flush=True)
        rows.append({"n": n, "packings": len(files),
                     "gamma": [{"upper": r["upper"], "value": r["power_law"]} for r in scan]})
    return rows


def parse_plan(items: list[str]) -> list[tuple[int, int]]:
    """"N:COUNT" items as (N, count) pairs, in the order given."""
    plan = []
    for item in items:
        try:
            n, count = (int(part) for part in item.split(":"))
        except ValueError:
            raise SystemExit(f"--plan takes N:COUNT items (e.g. 1024:80), got {item!r}") from None
        plan.append((n, count))
    return plan


def schedule(plan: list[tuple[int, int]], first_seed: int) -> list[tuple[int, int]]:
    """(N, seed) in the order made: the sizes of the plan interleaved in proportion to their
    counts (next, the size with the smallest share of its count done; ties: the smaller N),
    so that an interrupted run leaves every size with its share."""
    done = {n: 0 for n, _ in plan}
    counts = dict(plan)
    order = []
    while any(done[n] < counts[n] for n in counts):
        n = min((n for n in counts if done[n] < counts[n]),
                key=lambda n: (done[n] / counts[n], n))
        order.append((n, first_seed + done[n]))
        done[n] += 1
    return order


def folder_rows(out: Path) -> list[dict]:
    """Every packing record under `out` (certified and failed)."""
    rows = []
    for path in sorted(out.glob("d*_n*/packing_*.json")):
        rows.append(json.loads(path.read_text()))
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="folder of the ensembles")
    parser.add_argument("--plan", nargs="+", default=["1024:80", "2048:40", "4096:20", "8192:10"],
                        help="N:COUNT per size, made in this order")
    parser.add_argument("--d", type=int, default=3)
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--lock", default="none",
                        help="lock file held for each packing ('none', the default: no lock)")
    parser.add_argument("--max-minutes", type=float, default=None)
    parser.add_argument("--retry-failed", action="store_true")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--estimate", action="store_true",
                        help="fit the packings made and print the packings needed")
    parser.add_argument("--window-scan", action="store_true",
                        help="fit gamma of the packings made against the window's top")
    args = parser.parse_args(argv)
    if args.estimate or args.window_scan:
        rows = (estimate if args.estimate else window_scan_rows)(args.out, args.d)
        if args.json is not None:
            args.json.write_text(json.dumps(rows, indent=1) + "\n")
        return
    lock = None if args.lock == "none" else args.lock
    start = time.monotonic()
    print("| N | seed | quench s | jam s | LPs | phi_J | force balance | certified |")
    print("|---|---|---|---|---|---|---|---|", flush=True)
    for n, seed in schedule(parse_plan(args.plan), args.first_seed):
        folder = args.out / f"d{args.d}_n{n}"
        folder.mkdir(parents=True, exist_ok=True)
        done = (folder / f"packing_{seed}.npz").exists()
        failed = (folder / f"packing_{seed}.failed.json").exists()
        if done or (failed and not args.retry_failed):
            continue
        if args.max_minutes is not None and time.monotonic() - start > 60 * args.max_minutes:
            print(f"stopped after {args.max_minutes:g} minutes", flush=True)
            return _finish(args)
        row = make_packing(n, args.d, seed, folder, lock)
        print(f"| {n} | {seed} | {row['quench_s']:.1f} | {row['jam_s']:.1f} | "
              f"{row.get('lps', '-')} | {row.get('phi', float('nan')):.6f} | "
              f"{row.get('force_balance', float('nan')):.1e} | {row['certified']} |",
              flush=True)
    _finish(args)


def _finish(args) -> None:
    """The count of certified packings per size; the rows as JSON when asked."""
    rows = folder_rows(args.out)
    for n in sorted({row["n"] for row in rows}):
        mine = [row for row in rows if row["n"] == n and row["d"] == args.d]
        certified = sum(row["certified"] for row in mine)
        print(f"N = {n}: {certified} certified packings", flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
