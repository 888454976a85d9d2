"""The two routes over an ensemble: constant-rate LS packings (from random centres to
p = 1e5, as ``bench/routes.py --make ls``), each jammed by the LP route and by the relaxed
route. Per route: the critical exponents γ, θ_e, θ_ℓ and θ pooled over the certified
packings (`calippso.analysis.critical_exponents`, defaults) against the literature, mean φ_J,
the median displacement from the input, the contacts the two routes share, wall time and LPs.

Inputs and results are kept in ``--keep DIR``: the inputs as ``ls_N<N>_d<d>_seed<k>.npz``,
the results as ``jam_<route>_seed<k>.npz`` (as `calippso report` reads them) with their row
(wall time included) in ``row_<route>_seed<k>.json``. A second run skips every packing
already there, so an interrupted run resumes.

    python bench/route_exponents.py --keep DIR --seeds 1-20 --json route_exponents.json
    calippso report DIR/jam_relaxed_*.npz

A route that has not finished after ``--lp-limit`` seconds is stopped after its current LP;
it is then listed but left out of the exponents, as is a route that `jam` refuses
(``max_displacement``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import calippso
from calippso.analysis import critical_exponents
from routes import contact_keys, make_input, result_row, time_limit
from routes import format_row as route_row

#: The routes compared, in the order they run.
ROUTES = ("lp", "relaxed")


def parse_seeds(words: list[str]) -> list[int]:
    """Seeds from words such as ``1 2 3`` or ``1-20``."""
    seeds = []
    for word in words:
        first, _, last = word.partition("-")
        seeds.extend(range(int(first), int(last or first) + 1))
    return seeds


def jam_one(packing: calippso.Packing, route: str, seed: int, keep: Path,
            limit: float) -> dict:
    """The row of one route on one packing, read from `keep` when there."""
    row_path = keep / f"row_{route}_seed{seed}.json"
    result_path = keep / f"jam_{route}_seed{seed}.npz"
    if row_path.exists():
        return json.loads(row_path.read_text())
    started = time.perf_counter()
    try:
        result = calippso.jam(packing, route=route, callback=time_limit(limit))
    except calippso.JammingError as error:
        row = {"seed": seed, "route": route, "wall_time": time.perf_counter() - started,
               "converged": False, "refused": str(error)}
    else:
        row = {"seed": seed, **result_row(result, route, time.perf_counter() - started)}
        result.save(result_path)
    row_path.write_text(json.dumps(row, indent=1))
    return row


def shared_contacts(seed: int, keep: Path) -> int | None:
    """Contacts the two routes' jamming points of packing `seed` share (None if one is
    missing)."""
    paths = [keep / f"jam_{route}_seed{seed}.npz" for route in ROUTES]
    if not all(path.exists() for path in paths):
        return None
    first, second = (contact_keys(calippso.load_result(path)) for path in paths)
    return int(np.intersect1d(first, second).size)


def format_row(row: dict) -> str:
    shared = "" if "refused" in row else f" shared {row.get('shared_contacts')}"
    return f"seed {row['seed']:3d} {route_row(row)}{shared}"


def summary(route: str, rows: list[dict], keep: Path) -> dict:
    """Means over the certified packings of `route`, and their pooled exponents."""
    done = [row for row in rows if row["route"] == route and row["converged"]]
    out = {"route": route, "packings": len([row for row in rows if row["route"] == route]),
           "certified": len(done)}
    if not done:
        return out
    phi = np.array([row["phi_j"] for row in done])
    shared = [row["shared_contacts"] / row["contacts"] for row in done
              if row.get("shared_contacts") is not None]
    out.update({
        "phi_j_mean": float(phi.mean()),
        "phi_j_sem": float(phi.std(ddof=1) / np.sqrt(phi.size)) if phi.size > 1 else 0.0,
        "displacement_median": float(np.median([row["displacement_median"] for row in done])),
        "displacement_max_median": float(np.median([row["displacement_max"] for row in done])),
        "shared_fraction_mean": float(np.mean(shared)) if shared else None,
        "wall_time_mean": float(np.mean([row["wall_time"] for row in done])),
        "wall_time_max": float(np.max([row["wall_time"] for row in done])),
        "lps_mean": float(np.mean([row["lps"] for row in done])),
        "lps_max": int(np.max([row["lps"] for row in done]))})
    results = [calippso.load_result(keep / f"jam_{route}_seed{row['seed']}.npz") for row in done]
    try:
        exponents = critical_exponents(results)
    except ValueError as error:
        out["exponents_error"] = str(error)
    else:
        out["exponents"] = {name: {"value": e.value, "interval": list(e.interval),
                                   "reference": e.reference, "points": e.fit.n_points}
                            for name, e in exponents.items()}
    return out


def format_summary(entry: dict) -> str:
    if not entry.get("certified"):
        return f"{entry['route']:8s} 0 of {entry['packings']} certified"
    lines = [f"{entry['route']:8s} {entry['certified']} of {entry['packings']} certified; "
             f"phi_J {entry['phi_j_mean']:.6f} ± {entry['phi_j_sem']:.6f}; displacement median "
             f"{entry['displacement_median']:.1e} (max, median over packings "
             f"{entry['displacement_max_median']:.1e}); shared contacts "
             + (f"{entry['shared_fraction_mean']:.1%}" if entry["shared_fraction_mean"] is not None
                else "-")
             + f"; {entry['wall_time_mean']:.1f} s (max {entry['wall_time_max']:.1f} s), "
             f"{entry['lps_mean']:.1f} LPs (max {entry['lps_max']})"]
    for name, e in entry.get("exponents", {}).items():
        lines.append(f"    {name:8s} {e['value']:.3f} [{e['interval'][0]:.3f}, "
                     f"{e['interval'][1]:.3f}]  reference {e['reference']:.3f}  "
                     f"({e['points']} points)")
    if "exponents_error" in entry:
        lines.append(f"    exponents: {entry['exponents_error']}")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--keep", type=Path, required=True,
                        help="folder of the inputs and results (a rerun resumes from it)")
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--d", type=int, default=3)
    parser.add_argument("--seeds", nargs="+", default=["1-20"], help="e.g. 1 2 3 or 1-20")
    parser.add_argument("--lp-limit", type=float, default=900.0,
                        help="stop a route after its LP that passes this many seconds")
    parser.add_argument("--json", type=Path, default=None, help="write rows and summary here")
    args = parser.parse_args()
    args.keep.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in parse_seeds(args.seeds):
        packing = make_input("ls", args.n, args.d, seed, args.keep)
        seed_rows = [jam_one(packing, route, seed, args.keep, args.lp_limit) for route in ROUTES]
        shared = shared_contacts(seed, args.keep)
        for row in seed_rows:
            row["shared_contacts"] = shared
            print(format_row(row), flush=True)
        rows.extend(seed_rows)
    summaries = [summary(route, rows, args.keep) for route in ROUTES]
    print(f"\nN = {args.n}, d = {args.d}, constant-rate LS to p = 1e5; per route:")
    for entry in summaries:
        print(format_summary(entry))
    if args.json is not None:
        args.json.write_text(json.dumps({"n": args.n, "d": args.d, "rows": rows,
                                         "summary": summaries}, indent=1))


if __name__ == "__main__":
    main()
