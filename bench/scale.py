"""How `calippso.jam` scales with N and d: prints one table row per input.

Every input is an LS packing made by our generator at reduced pressure --pressure (seed 1),
jammed in a fresh subprocess so that the peak resident memory (RSS) of each row is its own.
Run from the repository root:

    python bench/scale.py                                  # d = 3: N = 1k … 16k; d = 4, 5: 1k
    python bench/scale.py --cases 3:1024 3:2048 --timeout 900 --json scale.json
    python bench/scale.py --cache /tmp/ls-inputs     # keep the LS inputs for the next run

Columns: N, d, LPs, rows of the largest LP, total wall time of `jam` (s), wall time per LP,
share of it inside the LP solver, peak RSS (MB), phi_J, isostatic, force balance.
A case that exceeds --timeout is reported as such.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import textwrap

DEFAULT_CASES = ["3:1024", "3:2048", "3:4096", "3:8192", "3:16384", "4:1024", "5:1024"]

CHILD = textwrap.dedent("""
    import json, os, resource, sys, time
    import calippso
    d, n, pressure, cache = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
    path = os.path.join(cache, f"ls_d{d}_n{n}_p{pressure:g}_seed1.npz") if cache else ""
    if path and os.path.exists(path):
        start = calippso.read(path)
    else:
        import generators
        start = generators.lubachevsky_stillinger(generators.diameters.monodisperse(n), d=d,
                                                  target_pressure=pressure, seed=1).packing
        if path:
            calippso.write(start, path)
    clock = time.perf_counter()
    result = calippso.jam(start)
    total = time.perf_counter() - clock
    history = result.history
    print(json.dumps({
        "n": n, "d": d, "lps": result.iterations, "rows": int(history["rows"].max()),
        "total": total, "solver": float(history["solver_time"].sum()),
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "phi": result.phi, "isostatic": result.isostatic,
        "balance": result.force_balance, "converged": result.converged}))
""")


def run_case(d: int, n: int, pressure: float, timeout: float, cache: str = "") -> dict:
    """Generate (or read from `cache`) and jam one input in a subprocess; the row as a dict."""
    try:
        done = subprocess.run([sys.executable, "-c", CHILD, str(d), str(n), str(pressure), cache],
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
        return f"{head}  error: {row['error']}"
    per_lp = row["total"] / max(row["lps"], 1)
    return (f"{head} {row['lps']:>4} {row['rows']:>8} {row['total']:>9.1f} {per_lp:>7.2f} "
            f"{row['solver'] / row['total']:>7.1%} {row['rss_mb']:>8.0f} {row['phi']:>11.8f} "
            f"{'yes' if row['isostatic'] else 'NO':>4} {row['balance']:>8.1e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=DEFAULT_CASES, help="inputs as d:N")
    parser.add_argument("--pressure", type=float, default=1e5)
    parser.add_argument("--timeout", type=float, default=3600.0, help="seconds per case")
    parser.add_argument("--json", help="also write the rows to this JSON file")
    parser.add_argument("--cache", default="", help="folder where LS inputs are kept and reused")
    args = parser.parse_args()

    print(f"{'N':>6} {'d':>2} {'LPs':>4} {'rows':>8} {'total s':>9} {'s/LP':>7} "
          f"{'solver':>7} {'RSS MB':>8} {'phi_J':>11} {'iso':>4} {'balance':>8}", flush=True)
    rows = []
    for case in args.cases:
        d, n = (int(v) for v in case.split(":"))
        rows.append(run_case(d, n, args.pressure, args.timeout, args.cache))
        print(format_row(rows[-1]), flush=True)
        if args.json:
            with open(args.json, "w") as stream:
                json.dump(rows, stream, indent=1)


if __name__ == "__main__":
    main()
