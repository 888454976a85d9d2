"""`calippso.jamming_category` on jammed random packings: one table row per (d, N, seed).

Every input is a soft quench (`generators.soft_quench`) jammed by `calippso.jam` with the
quench's network: monodisperse spheres for d ≥ 3, the 50:50 mixture of discs with diameter
ratio 1.4 in d = 2 (equal discs crystallise). The category is timed on the `JammingResult`
(its contacts and forces), the best of `--repeat` calls. Run from the repository root:

    python bench/categories.py --cases 3:1024 --seeds 1 2 3 --json categories.json
    python bench/categories.py --cases 2:1024 3:1024 --seeds 1 2 3 --cache DIR

`--cache DIR` keeps the jammed inputs (`jammed_d{d}_n{N}_seed{seed}.npz`) and reads them on
later runs, so that `--make-only` can build them apart from the timed run.

Columns: d, N, seed, φ_J, stable particles, contacts, isostaticity gap, the category, the
class whose test failed and whether its witness opens contacts (else it keeps every contact
closed to first order), the seconds of each class's test and of the whole call, and the
time of making and jamming the input. The last lines count, per dimension, the collectively
jammed packings that are strictly jammed.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import generators
import calippso

#: Diameter ratio of the 50:50 mixture of discs in d = 2.
BIDISPERSE_RATIO = 1.4


def jammed(n: int, d: int, seed: int):
    """The jammed packing of one case, and the seconds it took to make."""
    sizes = (generators.diameters.bidisperse(n, BIDISPERSE_RATIO) if d == 2
             else generators.diameters.monodisperse(n))
    start = time.perf_counter()
    quench = generators.soft_quench(sizes, d, seed=seed)
    result = calippso.jam(quench.packing, network=quench.contacts)
    return result, time.perf_counter() - start


def cached(n: int, d: int, seed: int, cache: str | None):
    """`jammed`, read from or written to the folder `cache` when given (making time NaN
    when read)."""
    if cache is None:
        return jammed(n, d, seed)
    path = Path(cache) / f"jammed_d{d}_n{n}_seed{seed}.npz"
    if path.exists():
        return calippso.load_result(path), float("nan")
    result, making = jammed(n, d, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    result.save(path)
    return result, making


def row(n: int, d: int, seed: int, repeat: int, cache: str | None = None) -> dict:
    """Make, jam and classify one packing (see the module docstring for the columns)."""
    result, making = cached(n, d, seed, cache)
    best = None
    for _ in range(repeat):
        start = time.perf_counter()
        category = calippso.jamming_category(result)
        seconds = time.perf_counter() - start
        if best is None or seconds < best[1]:
            best = (category, seconds)
    category, seconds = best
    times = {test.name: test.seconds for test in category.tests}
    return {"d": d, "n": n, "seed": seed, "phi": result.phi, "converged": result.converged,
            "stable": result.n_stable, "contacts": result.n_contacts,
            "isostaticity_gap": result.isostaticity_gap, "category": category.category,
            "failed": category.failed or "", "opens": category.opens_contacts,
            "local_s": times.get("local", 0.0), "collective_s": times.get("collective", 0.0),
            "strict_s": times.get("strict", 0.0), "seconds": seconds, "make_s": making}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", nargs="+", default=["3:1024"], help="d:N")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1])
    parser.add_argument("--repeat", type=int, default=3, help="calls timed per packing")
    parser.add_argument("--json", help="write the rows to this file")
    parser.add_argument("--cache", help="folder of the jammed inputs (read, or made and kept)")
    parser.add_argument("--make-only", action="store_true",
                        help="only make the inputs into --cache")
    args = parser.parse_args()
    if args.make_only:
        for case in args.cases:
            d, n = (int(part) for part in case.split(":"))
            for seed in args.seeds:
                print(case, seed, f"{cached(n, d, seed, args.cache)[1]:.1f} s", flush=True)
        return
    header = (f"{'d':>2} {'N':>5} {'seed':>4} {'phi_J':>8} {'N_s':>5} {'N_c':>6} {'gap':>4} "
              f"{'category':>11} {'failed':>10} {'opens':>5} {'local s':>8} {'coll. s':>8} "
              f"{'strict s':>8} {'total s':>8} {'make s':>7}")
    print(header)
    rows = []
    for case in args.cases:
        d, n = (int(part) for part in case.split(":"))
        for seed in args.seeds:
            r = row(n, d, seed, args.repeat, args.cache)
            rows.append(r)
            print(f"{r['d']:>2} {r['n']:>5} {r['seed']:>4} {r['phi']:>8.5f} {r['stable']:>5} "
                  f"{r['contacts']:>6} {r['isostaticity_gap']:>4} {r['category']:>11} "
                  f"{r['failed']:>10} {str(r['opens']):>5} {r['local_s']:>8.3f} "
                  f"{r['collective_s']:>8.3f} {r['strict_s']:>8.3f} {r['seconds']:>8.3f} "
                  f"{r['make_s']:>7.1f}", flush=True)
    for d in sorted({r["d"] for r in rows}):
        of_d = [r for r in rows if r["d"] == d]
        collective = [r for r in of_d if r["category"] in ("collective", "strict")]
        strict = [r for r in collective if r["category"] == "strict"]
        print(f"d = {d}: {len(strict)} of {len(collective)} collectively jammed packings "
              f"are strictly jammed ({len(of_d)} packings)")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(rows, handle, indent=1)


if __name__ == "__main__":
    main()
