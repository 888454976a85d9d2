"""Cost of contact pivots against N: prints one table row per input (and writes JSON).

Each input is a soft-sphere quench (d = 3, seed 1, p = 1e-7; `generators.soft_quench`)
jammed with no LP (`jam(..., network=q.contacts)`). Its jammed network then has k contacts
swapped for some of the nearest pairs that are not contacts (random draws), chosen
so that the swapped network's Newton point overlaps no other pair and has non-positive
forces. `calippso.certification.pivots.pivot_to_jamming` runs from that point. Run from the repository
root:

    python bench/pivots.py --sizes 1024 2048 4096 --swaps 3
    python bench/pivots.py --sizes 16384 --cache /tmp/quench --json pivots.json

Columns: N, contacts swapped, pivots (degenerate), sparse LU factorisations, seconds of the
path, seconds per pivot, whether the path returned to the jammed network, and the relative
φ difference from it.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import calippso
from calippso.geometry.neighbors import NeighborSearch
from calippso.certification.newton import refine_isostatic
from calippso.certification.pivots import pivot_to_jamming
from calippso.geometry.rattlers import remove_rattlers

#: Nearest non-contacts from which the swaps are drawn.
SWAP_POOL = 24
#: Draws tried before giving up on finding a swapped network with a feasible Newton point.
DRAWS = 2000


def quench(n: int, cache: Path | None) -> tuple[calippso.Packing, np.ndarray]:
    """The d = 3 quench of N particles (seed 1, p = 1e-7) and its overlap network, from
    `cache` when there."""
    path = None if cache is None else cache / f"quench_d3_n{n}_p1e-07_seed1.npz"
    if path is not None and path.exists():
        with np.load(path) as stored:
            return calippso.read(path), stored["contacts"]
    import generators

    made = generators.soft_quench(generators.diameters.monodisperse(n), 3, seed=1,
                                  target_pressure=1e-7)
    if path is not None:
        cache.mkdir(parents=True, exist_ok=True)
        np.savez(path, positions=made.packing.positions, diameters=made.packing.diameters,
                 box=made.packing.box, contacts=made.contacts)
    return made.packing, made.contacts


def swapped_start(result, k: int, seed: int = 0):
    """Positions, diameters, box (mean diameters) of the jammed packing, and a network with k
    contacts swapped whose Newton point is feasible with non-positive forces."""
    packing = result.packing
    scale = packing.mean_diameter
    positions, diameters, box = (packing.positions / scale, packing.diameters / scale,
                                 packing.box / scale)
    n, d = packing.n, packing.d
    contacts, rattlers = result.contacts, result.rattlers
    search = NeighborSearch(positions, diameters, box)
    close = search.pairs_within(1.05 * diameters.max())
    outside = (~np.isin(close.i * n + close.j, contacts[:, 0] * n + contacts[:, 1])
               & ~rattlers[close.i] & ~rattlers[close.j])
    near = np.flatnonzero(outside)[np.argsort(close.gaps[outside])][:SWAP_POOL]
    rng = np.random.default_rng(seed)
    for _ in range(DRAWS):
        removed = rng.choice(contacts.shape[0], k, replace=False)
        added = rng.choice(near, k, replace=False)
        keep = np.ones(contacts.shape[0], dtype=bool)
        keep[removed] = False
        network = np.concatenate([contacts[keep],
                                  np.column_stack([close.i[added], close.j[added]])])
        if (remove_rattlers(n, d, network[:, 0], network[:, 1])[0] != rattlers).any():
            continue
        refined = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                                   ~rattlers)
        if refined is None or refined.positive:
            continue
        moved = NeighborSearch(refined.positions, refined.diameters, box)
        pairs = moved.pairs_within(1.01 * refined.diameters.max())
        other = (~np.isin(pairs.i * n + pairs.j, network[:, 0] * n + network[:, 1])
                 & ~rattlers[pairs.i] & ~rattlers[pairs.j])
        if np.any(pairs.gaps[other] < -1e-12):
            continue
        return positions, diameters, box, network, refined
    raise RuntimeError(f"no swapped network of {k} contacts with a feasible Newton point")


def run(n: int, k: int, cache: Path | None) -> dict:
    packing, hint = quench(n, cache)
    result = calippso.jam(packing, network=hint, network_first="require")
    positions, diameters, box, network, refined = swapped_start(result, k)
    clock = time.perf_counter()
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     result.rattlers, refined=refined)
    seconds = time.perf_counter() - clock
    row = {"n": n, "swaps": k, "seconds": seconds, "failure": failure}
    if path is not None and path.jammed:
        end = {tuple(pair) for pair in np.column_stack([path.i, path.j]).tolist()}
        row.update(pivots=path.pivots, degenerate=path.degenerate,
                   factorizations=path.factorizations,
                   returned=end == {tuple(pair) for pair in result.contacts.tolist()},
                   phi_difference=float(np.mean(path.refinement.diameters / diameters)) ** 3
                   - 1.0)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048, 4096])
    parser.add_argument("--swaps", type=int, default=3, help="contacts swapped (k)")
    parser.add_argument("--cache", type=Path, default=None, help="folder for the quenches")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    print(f"{'N':>6} {'k':>3} {'pivots':>7} {'degen':>6} {'LUs':>4} {'path s':>8} "
          f"{'s/pivot':>8} {'returned':>9} {'phi diff':>9}")
    rows = []
    for n in args.sizes:
        row = run(n, args.swaps, args.cache)
        rows.append(row)
        if "pivots" not in row:
            print(f"{n:6d} {args.swaps:3d}  failed after {row['seconds']:.1f} s: {row['failure']}")
            continue
        print(f"{n:6d} {args.swaps:3d} {row['pivots']:7d} {row['degenerate']:6d} "
              f"{row['factorizations']:4d} {row['seconds']:8.2f} "
              f"{row['seconds'] / max(row['pivots'], 1):8.3f} {str(row['returned']):>9} "
              f"{row['phi_difference']:9.1e}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
