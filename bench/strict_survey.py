"""Strict jamming of random packings: how often the collectively jammed ones are strictly
jammed, and the density a deformable box gains from them. One row per (d, N, seed).

Every input is a Lubachevsky–Stillinger state at reduced pressure `--pressure` (default
1e5): monodisperse spheres for d ≥ 3, the 50:50 mixture of discs with diameter ratio 1.4 in
d = 2 (equal discs crystallise). `calippso.jam` jams it in a fixed box; the fixed-box result
is classified by `calippso.jamming_category`; `calippso.jam(box="deformable")` then starts
from that jammed packing. Run from the repository root:

    python bench/strict_survey.py --cases 2:1024 3:1024 --seeds 1 2 3 4 5 --json survey.json

`--cache DIR` keeps the LS inputs (`ls_d{d}_n{N}_p{pressure}_seed{seed}.npz`, as
bench/deformable.py).

Columns: d, N, seed; the fixed-box result: φ_J, its category, the class whose test failed,
its stress anisotropy; the deformable run from it: φ, the gain, its category, its
isostaticity gap (strict count), stress anisotropy, force balance, stop reason and LPs; the seconds of the fixed jam, of
the category test and of the deformable run. The last lines count, per dimension, the
collectively jammed packings that are strictly jammed and give the mean φ and gain.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import calippso
from deformable import start


def row(n: int, d: int, seed: int, pressure: float, cache: str | None) -> dict:
    """One input: fixed-box jam, its category, the deformable run from it."""
    packing = start(n, d, seed, pressure, cache)
    began = time.perf_counter()
    fixed = calippso.jam(packing)
    fixed_s = time.perf_counter() - began
    began = time.perf_counter()
    category = calippso.jamming_category(fixed)
    category_s = time.perf_counter() - began
    began = time.perf_counter()
    deformable = calippso.jam(fixed.packing, box="deformable")
    deformable_s = time.perf_counter() - began
    return {"d": d, "n": n, "seed": seed, "pressure": pressure,
            "phi_fixed": fixed.phi, "fixed_converged": fixed.converged,
            "category_fixed": category.category, "failed": category.failed or "",
            "anisotropy_fixed": fixed.stress_anisotropy,
            "phi_deformable": deformable.phi, "phi_gain": deformable.phi - fixed.phi,
            "category_deformable": deformable.category or "",
            "converged": deformable.converged, "stop": deformable.stop_reason.name,
            "balance": deformable.force_balance, "gap": deformable.isostaticity_gap,
            "anisotropy": deformable.stress_anisotropy, "lps": deformable.iterations,
            "fixed_s": fixed_s, "category_s": category_s, "deformable_s": deformable_s}


def tally(rows: list[dict]) -> list[str]:
    """Per dimension: strictly jammed among the collectively jammed fixed-box results, and
    the mean φ before and after the deformable box."""
    lines = []
    for d in sorted({r["d"] for r in rows}):
        mine = [r for r in rows if r["d"] == d]
        collective = [r for r in mine if r["category_fixed"] in ("collective", "strict")]
        strict = [r for r in collective if r["category_fixed"] == "strict"]
        ended = [r for r in mine if r["category_deformable"] == "strict"]
        phi = np.array([r["phi_fixed"] for r in mine])
        after = np.array([r["phi_deformable"] for r in mine])
        lines.append(f"d = {d}: {len(strict)} / {len(collective)} collectively jammed are "
                     f"strictly jammed; the deformable box ends strictly jammed in "
                     f"{len(ended)} / {len(mine)}; phi {phi.mean():.5f} +- {phi.std():.5f} -> "
                     f"{after.mean():.5f} +- {after.std():.5f} (gain "
                     f"{(after - phi).mean():.1e})")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", nargs="+", default=["2:1024", "3:1024"], help="d:N")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3, 4, 5])
    parser.add_argument("--pressure", type=float, default=1e5)
    parser.add_argument("--json", help="write the rows to this file")
    parser.add_argument("--cache", help="folder of the LS inputs (read, or made and kept)")
    args = parser.parse_args()
    print(f"{'d':>2} {'N':>5} {'seed':>4} {'phi fixed':>9} {'cat. fixed':>10} {'failed':>6} "
          f"{'aniso f':>7} {'phi def.':>9} {'gain':>8} {'cat. def.':>9} {'gap':>4} "
          f"{'aniso d':>7} {'balance':>7} {'stop':>10} {'LPs':>4} {'fixed s':>7} {'cat. s':>6} {'def. s':>7}")
    rows = []
    for case in args.cases:
        d, n = (int(part) for part in case.split(":"))
        for seed in args.seeds:
            r = row(n, d, seed, args.pressure, args.cache)
            rows.append(r)
            print(f"{d:>2} {n:>5} {seed:>4} {r['phi_fixed']:>9.6f} {r['category_fixed']:>10} "
                  f"{r['failed']:>6} {r['anisotropy_fixed']:>7.1e} "
                  f"{r['phi_deformable']:>9.6f} {r['phi_gain']:>8.1e} "
                  f"{r['category_deformable']:>9} {r['gap']:>4} {r['anisotropy']:>7.0e} "
                  f"{r['balance']:>7.0e} {r['stop']:>10} "
                  f"{r['lps']:>4} {r['fixed_s']:>7.1f} {r['category_s']:>6.2f} "
                  f"{r['deformable_s']:>7.1f}", flush=True)
            if args.json:
                with open(args.json, "w") as handle:
                    json.dump(rows, handle, indent=1)
    for line in tally(rows):
        print(line)


if __name__ == "__main__":
    main()
