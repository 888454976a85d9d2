"""`jam(box="deformable")` against the fixed-box `jam` of the same input: one row per
(d, N, seed).

Every input is a Lubachevsky–Stillinger state at reduced pressure `--pressure` (default
1e5): monodisperse spheres for d ≥ 3, the 50:50 mixture of discs with diameter ratio 1.4 in
d = 2 (equal discs crystallise). Both runs start from it; each is timed once, the
best of `--repeat` calls. Run from the repository root:

    python bench/deformable.py --cases 3:1024 --seeds 1 2 3 --json deformable.json
    python bench/deformable.py --cases 2:1024 3:1024 --seeds 1 2 3 --cache DIR

`--cache DIR` keeps the LS inputs (`ls_d{d}_n{N}_p{pressure}_seed{seed}.npz`);
`--set KEY=VALUE` passes an option of `jam` to the deformable run only (e.g. `newton=False`
for the LP loop without the strict Newton stage).

Columns: d, N, seed; φ of the fixed-box and of the deformable run, their difference;
the deformable run's LPs, isostaticity gap (strict count), stress anisotropy, force balance,
whether it converged, which stage ended it ("newton": the strict Newton stage, "lp": the
LPs' tolerances), its category (`JammingResult.category`, "strict" when certified) and
the fixed-box result's (`calippso.jamming_category`, not timed); the seconds of each run and
their ratio; then, for each run, where its LP time goes: the LPs solved cold (interior
point), their seconds, the seconds of the warm ones (simplex from the last basis), and the
mean rows per LP.
"""

from __future__ import annotations

import argparse
import ast
import json
import time
from pathlib import Path

import numpy as np

import generators
import calippso

#: Diameter ratio of the 50:50 mixture of discs in d = 2.
BIDISPERSE_RATIO = 1.4


def start(n: int, d: int, seed: int, pressure: float, cache: str | None):
    """The LS input of one case (read from or written to `cache` when given)."""
    path = None if cache is None else Path(cache) / f"ls_d{d}_n{n}_p{pressure:g}_seed{seed}.npz"
    if path is not None and path.exists():
        return calippso.read(path)
    sizes = (generators.diameters.bidisperse(n, BIDISPERSE_RATIO) if d == 2
             else generators.diameters.monodisperse(n))
    packing = generators.lubachevsky_stillinger(sizes, d=d, target_pressure=pressure,
                                                seed=seed).packing
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        calippso.write(packing, path)
    return packing


def timed(packing, repeat: int, **options):
    """The result of `calippso.jam` and the seconds of the fastest of `repeat` calls."""
    best = None
    for _ in range(repeat):
        began = time.perf_counter()
        result = calippso.jam(packing, **options)
        seconds = time.perf_counter() - began
        if best is None or seconds < best[1]:
            best = (result, seconds)
    return best


def lp_profile(result) -> dict:
    """Where a run's LP time goes: the LPs solved cold (interior point) and warm (simplex
    from the last basis), the seconds of each, the mean rows per LP."""
    history = result.history
    lp = np.isin(history["stage"], ("lp", "cleanup"))
    cold = lp & (history["ipm_iterations"] > 0)
    return {"cold_lps": int(cold.sum()), "cold_s": float(history["solver_time"][cold].sum()),
            "warm_s": float(history["solver_time"][lp & ~cold].sum()),
            "rows": float(history["rows"][lp].mean()) if lp.any() else 0.0}


def row(n: int, d: int, seed: int, pressure: float, repeat: int, cache: str | None,
        options: dict) -> dict:
    """Both runs of one case (see the module docstring for the columns); `options` go to the
    deformable run."""
    packing = start(n, d, seed, pressure, cache)
    fixed, fixed_s = timed(packing, repeat)
    deformable, deformable_s = timed(packing, repeat, box="deformable", **options)
    return {"d": d, "n": n, "seed": seed, "pressure": pressure, "phi_fixed": fixed.phi,
            "phi_deformable": deformable.phi, "phi_gain": deformable.phi - fixed.phi,
            "lps_fixed": fixed.iterations, "lps_deformable": deformable.iterations,
            "gap": deformable.isostaticity_gap, "anisotropy": deformable.stress_anisotropy,
            "balance": deformable.force_balance, "converged": deformable.converged,
            "ended_by": str(deformable.history["stage"][-1]),
            "category": deformable.category or "",
            "category_fixed": calippso.jamming_category(fixed).category,
            "fixed_s": fixed_s, "deformable_s": deformable_s,
            "ratio": deformable_s / fixed_s,
            **{f"{key}_fixed": value for key, value in lp_profile(fixed).items()},
            **{f"{key}_deformable": value for key, value in lp_profile(deformable).items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", nargs="+", default=["3:1024"], help="d:N")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1])
    parser.add_argument("--pressure", type=float, default=1e5)
    parser.add_argument("--repeat", type=int, default=1, help="calls timed per run")
    parser.add_argument("--json", help="write the rows to this file")
    parser.add_argument("--cache", help="folder of the LS inputs (read, or made and kept)")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="options of the deformable run (Python literals)")
    args = parser.parse_args()
    options = {key: ast.literal_eval(value)
               for key, value in (item.split("=", 1) for item in args.set)}
    print(f"{'d':>2} {'N':>5} {'seed':>4} {'phi fixed':>9} {'phi def.':>9} {'gain':>8} "
          f"{'LPs f':>5} {'LPs d':>5} {'gap':>4} {'aniso':>7} {'balance':>7} {'conv':>5} "
          f"{'ended':>6} "
          f"{'category':>10} {'fixed cat.':>10} {'fixed s':>8} {'def. s':>8} {'ratio':>6} "
          f"{'cold f':>6} {'cold d':>6} {'cold s f':>8} {'cold s d':>8} {'warm s f':>8} "
          f"{'warm s d':>8} {'rows f':>7} {'rows d':>7}")
    rows = []
    for case in args.cases:
        d, n = (int(part) for part in case.split(":"))
        for seed in args.seeds:
            r = row(n, d, seed, args.pressure, args.repeat, args.cache, options)
            rows.append(r)
            print(f"{d:>2} {n:>5} {seed:>4} {r['phi_fixed']:>9.6f} {r['phi_deformable']:>9.6f} "
                  f"{r['phi_gain']:>8.1e} {r['lps_fixed']:>5} {r['lps_deformable']:>5} "
                  f"{r['gap']:>4} {r['anisotropy']:>7.0e} {r['balance']:>7.0e} "
                  f"{str(r['converged']):>5} {r['ended_by']:>6} {r['category']:>10} {r['category_fixed']:>10} "
                  f"{r['fixed_s']:>8.2f} {r['deformable_s']:>8.2f} {r['ratio']:>6.2f} "
                  f"{r['cold_lps_fixed']:>6} {r['cold_lps_deformable']:>6} "
                  f"{r['cold_s_fixed']:>8.1f} {r['cold_s_deformable']:>8.1f} "
                  f"{r['warm_s_fixed']:>8.1f} {r['warm_s_deformable']:>8.1f} "
                  f"{r['rows_fixed']:>7.0f} {r['rows_deformable']:>7.0f}", flush=True)
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(rows, handle, indent=1)


if __name__ == "__main__":
    main()
