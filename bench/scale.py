"""How making and jamming a packing scale with N and d: prints one table row per input.

Every input is made by our generator (seed 1, or --seed) and jammed in a fresh subprocess,
so that the peak resident memory (RSS) of each row is its own. `--generator ls` (default): LS to reduced
pressure --pressure, then `jam`. `--generator quench`: the soft-sphere quench
(`generators.soft_quench`), then `jam` with the quench's overlap network as the hint
(network first: certified by Newton, no LP). Run from the repository root:

    python bench/scale.py                                  # d = 3: N = 1k … 16k; d = 4, 5: 1k
    python bench/scale.py --cases 3:1024 3:2048 --timeout 900 --json scale.json
    python bench/scale.py --cache /tmp/ls-inputs     # keep the LS inputs for the next run
    python bench/scale.py --cases 4:1024 --set interior_point=hipo   # further jam options
    python bench/scale.py --from-json a.json b.json --plot docs/images/scale.png
    python bench/scale.py --generator quench --cases 3:1024 3:4096 3:16384 --json quench.json
    python bench/scale.py --generator quench --quench-pressure 1e-6 --cases 4:1024
    python bench/scale.py --generator quench --seed 2 --cases 4:1024 5:1024
    python bench/scale.py --generator quench --quench-pressure 1e-8 --cases 3:16384 \
        --set network_first=require          # fails fast when network first cannot settle
    python bench/scale.py --generator quench --settle-excess 16 --cases 3:8192  # ends the
        # quench at the first overlap network that network first certifies
    python bench/scale.py --generator quench --no-hint --cases 3:16384 --cache DIR \
        --timeout 7200                       # positions only: jam guesses the network itself
    python bench/scale.py --container walls:x --cases 3:1024      # flat walls at x = 0, L
    python bench/scale.py --container cylinder:x,y --cases 3:1024  # a cylinder along z

With --from-json no case is run: the rows are read back (later files win for the same N, d),
printed, and with --plot drawn as wall time and LPs against N on log-log axes, with the
fitted exponent of the wall time over the d = 3 rows.

Columns: N, d, seconds to generate the input (0 when read from --cache), LPs, rows of the
largest LP (candidate pairs when no LP ran), total wall time of `jam` (s), wall time per LP,
both (make + jam, s), share of the jam time inside the LP solver, peak RSS (MB), phi_J,
isostatic, force balance, smallest relative gap of the result (≥ −1e-12: no overlap).
The growth exponents of the jam and end-to-end times over the d = 3 rows close the table.
A case that exceeds --timeout is reported as such, and one whose `jam` raises JammingError
(with `--set network_first=require`) with the time spent making and jamming it.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import textwrap

from jam import parse_options

DEFAULT_CASES = ["3:1024", "3:2048", "3:4096", "3:8192", "3:16384", "4:1024", "5:1024"]

CHILD = textwrap.dedent("""
    import functools, json, os, resource, sys, time
    import numpy as np
    import calippso
    from calippso.geometry.neighbors import NeighborSearch
    from calippso.geometry.contact_network import walls_near_contact
    d, n, pressure, cache = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
    options, generator, quench_pressure = json.loads(sys.argv[5]), sys.argv[6], sys.argv[7]
    seed, container, settle_excess = int(sys.argv[8]), sys.argv[9], int(sys.argv[10])
    hint = sys.argv[11] == "hint"
    boundaries = calippso.Boundaries.all_periodic(d)
    if container != "periodic":
        kind, axes = container.split(":")
        boundaries = getattr(calippso.Boundaries, kind)(d, axes.split(","))
    if quench_pressure == "default":
        from generators import default_target_pressure
        quench_pressure = default_target_pressure(n, d, boundaries)
    quench_pressure = float(quench_pressure)
    name = (f"ls_d{d}_n{n}_p{pressure:g}" if generator == "ls"
            else f"quench_d{d}_n{n}_p{quench_pressure:g}")
    if container != "periodic":
        name += "_" + container.replace(":", "_").replace(",", "")
    path = os.path.join(cache, f"{name}_seed{seed}.npz") if cache else ""
    clock = time.perf_counter()
    settle, tried = None, 0.0
    if path and os.path.exists(path):
        start = calippso.read(path)
        with np.load(path) as stored:
            network = stored["contacts"] if "contacts" in stored.files else None
        generate = 0.0
    else:
        import generators
        sizes = generators.diameters.monodisperse(n)
        walled = {} if boundaries.is_periodic else {"boundaries": boundaries}
        if generator == "ls":
            made = generators.lubachevsky_stillinger(sizes, d=d, target_pressure=pressure,
                                                     seed=seed, **walled)
        else:
            if settle_excess >= 0:
                walled["settle"] = calippso.NetworkFirstSettle(functools.partial(
                    calippso.jam, network_first="require", **options))
                walled["settle_excess"] = settle_excess
            made = generators.soft_quench(sizes, d, seed=seed, target_pressure=quench_pressure,
                                          **walled)
        start, network = made.packing, getattr(made, "contacts", None)
        generate = time.perf_counter() - clock
        settle = walled.get("settle")
        if settle is not None:
            tried = sum(seconds for _, seconds, _ in settle.tried)
            generate -= tried
        if path:
            extra = {} if network is None else {"contacts": network}
            if not boundaries.is_periodic:
                extra["boundaries"] = str(boundaries)
            np.savez(path, positions=start.positions, diameters=start.diameters,
                     box=start.box, **extra)
    clock = time.perf_counter()
    settled = "" if settle is None else settle.summary()
    try:
        if settle is not None and settle.certified is not None:
            result = settle.certified
        else:
            result = calippso.jam(start, network=network if hint else None, **options)
    except calippso.JammingError as error:   # e.g. network_first="require" refused
        print(json.dumps({"n": n, "d": d, "generator": generator, "generate": generate,
                          "total": time.perf_counter() - clock + tried, "error": str(error),
                          "settled": settled}))
        sys.exit(0)
    total = time.perf_counter() - clock + tried
    history = result.history
    packing = result.packing
    search = NeighborSearch(packing.positions, packing.diameters, packing.box,
                            packing.boundaries.periodic)
    smallest_gap = min(search.pairs_near_contact().smallest_gap(),
                       walls_near_contact(search, packing.boundaries).smallest_gap())
    print(json.dumps({
        "n": n, "d": d, "generator": generator, "generate": generate, "container": container,
        "hint": hint and network is not None,
        "lps": result.iterations, "rows": int(history["rows"].max()),
        "total": total, "solver": float(history["solver_time"].sum()),
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "phi": result.phi, "isostatic": result.isostatic,
        "balance": result.force_balance, "converged": result.converged,
        "min_gap": smallest_gap, "settled": settled,
        "stop_reason": str(result.stop_reason.value),
        "pivots": int(np.nansum(history["pivots"])),
        "notes": list(result.notes)}))
""")


def run_case(d: int, n: int, pressure: float, timeout: float, cache: str = "",
             options: dict | None = None, generator: str = "ls",
             quench_pressure: float | None = None, seed: int = 1,
             container: str = "periodic", settle_excess: int | None = None,
             hint: bool = True) -> dict:
    """Generate (or read from `cache`) and jam one input in a subprocess with the jam
    `options`, in the `container` ("periodic", "walls:AXES" or "cylinder:AXES"); the row as
    a dict. `settle_excess` (quench only): end the quench at the first overlap network
    within that many contacts of isostatic that network first certifies
    (`calippso.NetworkFirstSettle`). Without `hint`, `jam` gets the positions only, not the
    quench's overlap network."""
    try:
        done = subprocess.run([sys.executable, "-c", CHILD, str(d), str(n), str(pressure), cache,
                               json.dumps(options or {}), generator,
                               "default" if quench_pressure is None else str(quench_pressure),
                               str(seed), container,
                               str(-1 if settle_excess is None else settle_excess),
                               "hint" if hint else "no-hint"],
                              capture_output=True, text=True, timeout=timeout, check=True)
    except subprocess.TimeoutExpired:
        return {"n": n, "d": d, "timeout": timeout}
    except subprocess.CalledProcessError as error:
        return {"n": n, "d": d, "error": error.stderr.strip().splitlines()[-1]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def format_row(row: dict) -> str:
    head = f"{row['n']:>6} {row['d']:>2}"
    if "timeout" in row:
        return f"{head}  not finished within {row['timeout']:.0f} s"
    if "error" in row:
        spent = (f" after {row.get('generate', float('nan')):.1f} s making and "
                 f"{row['total']:.1f} s jamming" if "total" in row else "")
        return f"{head}  error{spent}: {row['error']}"
    per_lp = row["total"] / max(row["lps"], 1)
    both = row.get("generate", float("nan")) + row["total"]
    return (f"{head} {row.get('generate', float('nan')):>9.1f} {row['lps']:>4} {row['rows']:>8} "
            f"{row['total']:>9.1f} {per_lp:>7.2f} {both:>9.1f} "
            f"{row['solver'] / row['total']:>7.1%} {row['rss_mb']:>8.0f} {row['phi']:>11.8f} "
            f"{'yes' if row['isostatic'] else 'NO':>4} {row['balance']:>8.1e} "
            f"{row.get('min_gap', float('nan')):>9.1e}")


def growth_exponent(rows: list[dict], end_to_end: bool = False) -> float | None:
    """Least-squares slope of log(time) against log(N) over the finished d = 3 rows: the wall
    time of `jam`, or with `end_to_end` that of making the input and jamming it."""
    import numpy as np

    done = [row for row in rows if row["d"] == 3 and "total" in row and "error" not in row]
    if len(done) < 2:
        return None
    times = [r["total"] + (r.get("generate", 0.0) if end_to_end else 0.0) for r in done]
    return float(np.polyfit(np.log([r["n"] for r in done]), np.log(times), 1)[0])


def plot(rows: list[dict], path: str) -> None:
    """Wall time and LP count against N (d = 3; d = 4, 5 as single points), log-log."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (left, right) = plt.subplots(1, 2, figsize=(9, 3.8))
    for d, marker in ((3, "o"), (4, "s"), (5, "^")):
        done = sorted((r for r in rows if r["d"] == d and "total" in r and "error" not in r),
                      key=lambda r: r["n"])
        if not done:
            continue
        n = [r["n"] for r in done]
        left.loglog(n, [r["total"] for r in done], marker=marker, label=f"d = {d}")
        right.loglog(n, [r["lps"] for r in done], marker=marker, label=f"d = {d}")
    slope = growth_exponent(rows)
    title = "wall time of jam (LS input, p = 1e5)"
    left.set(xlabel="N", ylabel="s", title=title + (f"\nd = 3 exponent {slope:.2f}"
                                                     if slope is not None else ""))
    right.set(xlabel="N", ylabel="LPs", title="LPs solved")
    for axes in (left, right):
        axes.legend()
        axes.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=120)


def print_rows(rows: list[dict]) -> None:
    print(f"{'N':>6} {'d':>2} {'make s':>9} {'LPs':>4} {'rows':>8} {'jam s':>9} {'s/LP':>7} "
          f"{'both s':>9} {'solver':>7} {'RSS MB':>8} {'phi_J':>11} {'iso':>4} {'balance':>8} "
          f"{'min gap':>9}", flush=True)
    for row in rows:
        print(format_row(row), flush=True)


def print_exponents(rows: list[dict]) -> None:
    """The d = 3 growth exponents of the jam and end-to-end wall times, when there are any."""
    for label, end_to_end in (("jam", False), ("make + jam", True)):
        slope = growth_exponent(rows, end_to_end)
        if slope is not None:
            print(f"d = 3 wall-time exponent of {label} (log-log fit): {slope:.2f}")


def read_rows(paths: list[str]) -> list[dict]:
    """Rows of earlier --json files; a later file's row replaces an earlier one (same N, d)."""
    merged: dict[tuple[int, int], dict] = {}
    for path in paths:
        with open(path) as stream:
            for row in json.load(stream):
                merged[(row["d"], row["n"])] = row
    return sorted(merged.values(), key=lambda r: (r["d"], r["n"]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=DEFAULT_CASES, help="inputs as d:N")
    parser.add_argument("--pressure", type=float, default=1e5)
    parser.add_argument("--generator", choices=["ls", "quench"], default="ls",
                        help="LS to --pressure, or the soft-sphere quench (network first)")
    parser.add_argument("--quench-pressure", type=float, default=None,
                        help="target_pressure of the soft-sphere quench (default: its own, "
                             "generators.default_target_pressure)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the generator")
    parser.add_argument("--timeout", type=float, default=3600.0, help="seconds per case")
    parser.add_argument("--json", help="also write the rows to this JSON file")
    parser.add_argument("--cache", default="", help="folder where LS inputs are kept and reused")
    parser.add_argument("--from-json", nargs="+", metavar="JSON",
                        help="run nothing: read rows written by --json")
    parser.add_argument("--plot", help="draw the rows to this image (needs matplotlib)")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="further jam options, e.g. interior_point=hipo")
    parser.add_argument("--settle-excess", type=int, default=None, metavar="K",
                        help="quench only: network first tries each settled overlap network "
                             "within K contacts of isostatic during the quench, which ends at "
                             "the first one certified (jam s is then the time of the tries)")
    parser.add_argument("--no-hint", action="store_true",
                        help="quench only: jam the positions alone, without the quench's "
                             "overlap network as the hint")
    parser.add_argument("--container", default="periodic",
                        help="periodic (default), walls:AXES or cylinder:AXES, e.g. walls:x,y")
    args = parser.parse_args()
    options = parse_options(args.set)
    if args.settle_excess is not None and (args.generator != "quench" or args.cache):
        parser.error("--settle-excess takes --generator quench and no --cache")

    if args.from_json:
        rows = read_rows(args.from_json)
        print_rows(rows)
        print_exponents(rows)
        if args.plot:
            plot(rows, args.plot)
        return
    print_rows([])
    rows = []
    for case in args.cases:
        d, n = (int(v) for v in case.split(":"))
        rows.append(run_case(d, n, args.pressure, args.timeout, args.cache, options,
                             args.generator, args.quench_pressure, args.seed,
                             args.container, args.settle_excess, not args.no_hint))
        print(format_row(rows[-1]), flush=True)
        if args.json:
            with open(args.json, "w") as stream:
                json.dump(rows, stream, indent=1)
    print_exponents(rows)
    if args.plot:
        plot(rows, args.plot)


if __name__ == "__main__":
    main()
