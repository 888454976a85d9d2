"""Jam one input by both routes, the CALiPPSO loop from the input (``route="lp"``) and the
relaxed route (``route="relaxed"``), and compare: wall time, LPs, φ_J, the distance of the
jamming point from the input, and the contacts the two jamming points share.

Inputs: a file (``--input``, any format `calippso.read` takes, e.g. the shared
PackingGeneration folders), or one made here at a constant rate (``--make ls``: LS from
random centres to p = 1e5; ``--make fbls``: force-biased, then LS from it to p = 1e5), kept
in ``--cache`` so that both routes and later runs jam the same packing.

    python bench/routes.py --make fbls --n 2048 --d 3 --seed 1 --cache /tmp/inputs \\
        --json routes.json
    python bench/routes.py --input ../shared/data/mono_N1000_fba1e-3_then_ls1e-2_seed11
    python bench/routes.py --make ls --n 1024 --d 5 --routes relaxed

A route that has not finished after ``--lp-limit`` seconds is stopped after its current LP
(the row then says so); a route that `jam` refuses (``max_displacement``) gives a row with
the refusal.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import calippso

#: Reduced pressure of the constant-rate LS inputs made here.
LS_PRESSURE = 1e5
#: Diameters of the inputs made here: equal spheres, or bidisperse 1:1.4 discs in d = 2.
DISC_RATIO = 1.4
#: Quantiles of the particles' displacements from the input that a row reports.
QUANTILES = (0.9, 0.99, 0.999)
#: ... and the displacements (mean diameters) above which it counts the particles.
FAR = (0.1, 0.25, 0.5)


def make_input(kind: str, n: int, d: int, seed: int, cache: Path | None) -> calippso.Packing:
    """A constant-rate input: "ls" (LS from random centres) or "fbls" (FB, then LS from
    it), to reduced pressure `LS_PRESSURE`; read from `cache` when made before."""
    path = None if cache is None else cache / f"{kind}_N{n}_d{d}_seed{seed}.npz"
    if path is not None and path.exists():
        return calippso.read(path)
    import generators
    from generators import diameters

    sizes = diameters.bidisperse(n, DISC_RATIO, seed=seed) if d == 2 else \
        diameters.monodisperse(n)
    if kind == "fbls":
        start = generators.force_biased(sizes, d, seed=seed).packing
        packing = generators.lubachevsky_stillinger(start=start, target_pressure=LS_PRESSURE,
                                                    seed=seed).packing
    else:
        packing = generators.lubachevsky_stillinger(sizes, d, target_pressure=LS_PRESSURE,
                                                    seed=seed).packing
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        calippso.write(packing, path)
    return packing


def time_limit(seconds: float):
    """A `jam` callback that stops the run after `seconds`."""
    started = time.perf_counter()
    return lambda record: time.perf_counter() - started > seconds


def run_route(packing: calippso.Packing, route: str, limit: float,
              max_displacement: float | None = None) -> tuple[dict, np.ndarray]:
    """One route's row and its contact keys (i·N + j, sorted); a route that `jam` refuses
    (it moved a particle further than its `max_displacement`, passed to the relaxed and auto
    routes; None: `jam`'s default) gives a row saying so."""
    bound = {} if route == "lp" or max_displacement is None else \
        {"max_displacement": max_displacement}
    started = time.perf_counter()
    try:
        result = calippso.jam(packing, route=route, callback=time_limit(limit), **bound)
    except calippso.JammingError as error:
        return {"route": route, "wall_time": time.perf_counter() - started, "refused": str(error),
                "phi_input": packing.phi}, np.zeros(0, np.int64)
    row = result_row(result, route, time.perf_counter() - started)
    row.update(displacement_spread(packing, result))
    return row, contact_keys(result)


def displacement_spread(packing: calippso.Packing, result: calippso.JammingResult) -> dict:
    """Quantiles (`QUANTILES`) of the particles' displacements from the input `packing`,
    and how many particles moved further than each of `FAR`, the farthest one a rattler or
    not (mean diameters of the input)."""
    from calippso.geometry.periodic import displacements

    lengths, _ = displacements(packing.positions, result.packing.positions, packing.box,
                               packing.periodic)
    lengths /= packing.mean_diameter
    farthest = int(np.argmax(lengths))
    return {"displacement_quantiles": {str(q): float(np.quantile(lengths, q))
                                       for q in QUANTILES},
            "displacement_beyond": {str(x): int(np.count_nonzero(lengths > x)) for x in FAR},
            "farthest_is_rattler": bool(result.rattlers[farthest])}


def result_row(result: calippso.JammingResult, route: str, seconds: float) -> dict:
    """The row of one route's result that took `seconds` of wall time."""
    return {"route": route, "wall_time": seconds, "lps": result.iterations,
            "converged": result.converged, "stop_reason": str(result.stop_reason.value),
            "phi_input": result.phi_input, "phi_j": result.phi,
            "displacement_median": result.displacement_median,
            "displacement_max": result.displacement_max, "contacts": result.n_contacts,
            "isostaticity_gap": result.isostaticity_gap, "force_balance": result.force_balance,
            "relax_time": (seconds - float(result.history["wall_time"][-1])
                           if route != "lp" and result.route == "relaxed" else 0.0),
            "notes": result.notes}


def contact_keys(result: calippso.JammingResult) -> np.ndarray:
    """The result's contacts as sorted keys i·N + j (i < j)."""
    pairs = np.sort(result.contacts, axis=1)
    return np.sort(pairs[:, 0] * result.packing.n + pairs[:, 1])


def compare(packing: calippso.Packing, routes: list[str], limit: float,
            max_displacement: float | None = None) -> list[dict]:
    """Rows of every route, with the contacts each shares with the first route's."""
    rows, keys = [], []
    for route in routes:
        row, contacts = run_route(packing, route, limit, max_displacement)
        rows.append(row)
        keys.append(contacts)
        print(format_row(row), flush=True)
    for row, contacts in zip(rows, keys):
        row["shared_contacts"] = int(np.intersect1d(contacts, keys[0]).size)
    return rows


def format_row(row: dict) -> str:
    if "refused" in row:
        return f"{row['route']:8s} {row['wall_time']:8.1f} s  refused: {row['refused']}"
    # rows saved before the relaxation was timed have no "relax_time"
    relaxation = row.get("relax_time", 0.0)
    return (f"{row['route']:8s} {row['wall_time']:8.1f} s (relaxation {relaxation:.1f} s) "
            f"{row['lps']:4d} LPs "
            f"{'jammed' if row['converged'] else row['stop_reason']:>10s} "
            f"phi_J {row['phi_j']:.6f} (input {row['phi_input']:.6f}) "
            f"displacement median {row['displacement_median']:.1e} max "
            f"{row['displacement_max']:.1e}  contacts {row['contacts']}"
            + ("" if "displacement_quantiles" not in row else
               "\n         displacement quantiles "
               + " ".join(f"{q}: {x:.2g}" for q, x in row["displacement_quantiles"].items())
               + "; particles beyond "
               + " ".join(f"{x}: {k}" for x, k in row["displacement_beyond"].items())
               + f"; the farthest {'a rattler' if row['farthest_is_rattler'] else 'stable'}")
            + "".join(f"\n         {note}" for note in row["notes"]
                      if note.startswith("the soft-sphere relaxation")))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--input", type=Path, default=None, help="a packing file or folder")
    parser.add_argument("--make", choices=("ls", "fbls"), default="ls")
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--d", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--cache", type=Path, default=None,
                        help="folder of the inputs made here")
    parser.add_argument("--routes", nargs="+", default=["lp", "relaxed"],
                        choices=("lp", "relaxed", "auto"))
    parser.add_argument("--lp-limit", type=float, default=900.0,
                        help="stop a route after its LP that passes this many seconds")
    parser.add_argument("--max-displacement", type=float, default=None,
                        help="max_displacement of the relaxed and auto routes (mean "
                             "diameters; default: jam's)")
    parser.add_argument("--early-excess", default=None,
                        help="calippso.routes.EARLY_MAX_EXCESS for this run: an integer, or "
                             "'none' for the whole ladder (default: the library's)")
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    args = parser.parse_args()
    if args.early_excess is not None:
        import calippso.routes

        calippso.routes.EARLY_MAX_EXCESS = (None if args.early_excess == "none"
                                            else int(args.early_excess))
    if args.input is not None:
        packing, name = calippso.read(args.input), str(args.input)
    else:
        made = time.perf_counter()
        packing = make_input(args.make, args.n, args.d, args.seed, args.cache)
        name = f"{args.make} N={args.n} d={args.d} seed={args.seed}"
        print(f"input made or read in {time.perf_counter() - made:.1f} s", flush=True)
    from calippso.routes import gap_spread, lp_route_slow

    prediction = lp_route_slow(packing)
    near, spread = gap_spread(packing)
    print(f"{name}: N = {packing.n}, d = {packing.d}, phi = {packing.phi:.6f}; {near} pairs "
          f"near contact, gaps spread over {spread:.1f} decades; route 'auto': "
          f"{'relaxed, ' + prediction if prediction else 'lp'}", flush=True)
    rows = compare(packing, args.routes, args.lp_limit, args.max_displacement)
    print("shared contacts with the first route: "
          + ", ".join(f"{row['route']} {row['shared_contacts']}/{row.get('contacts', 0)}"
                      for row in rows))
    if args.json is not None:
        args.json.write_text(json.dumps({"input": name, "n": packing.n, "d": packing.d,
                                         "near_pairs": near, "spread": spread, "auto": prediction,
                                         "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
