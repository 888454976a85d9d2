"""Anatomy of the wandering phase: how the LP steps of one `calippso.jam` run move the packing.

Prints one row per LP and a summary. Run from the repository root:

    python studies/wandering.py                          # our LS, N = 1024, d = 3, p = 1e5, seed 2
    python studies/wandering.py --seed 1 --pressure 1e12
    python studies/wandering.py --input ../shared/data/mono_N1000_fba1e-3_then_ls1e-2_seed11

Columns (lengths in mean diameters):
- `max|s|/b`: the largest displacement of a stable particle over the LP's step bound b.
- `cos`: cosine between this LP's displacement field and the previous one (all particles).
- `top5%`: share of Σ|s_i|² carried by the 5 % of particles that move most (0.05: uniform).
- `α = 1, 1.5, 2`: √Γ − 1 of the real (not linearised) problem at the start of the LP moved
  by α times its step: the largest common growth without overlap, negative when some pair
  would overlap by that fraction. At α = 1 it is the LP's own growth or a little more.
- `cold`: solved by interior point + crossover, not warm-started (taken to be an LP whose
  solver time exceeds 4 × the median of the run: cold LPs cost 5–15 times a warm one).
The summary gives the displacement from the input to the jammed packing, without the common
translation of all particles.

--second-order re-solves every LP of the run, cold, from its start configuration and bound,
once as built and once with the term |s_ij|² of that solution's own step added to every row
(a second-order correction of the linearisation), and reports how often the corrected step
overlaps (exact distances) and how far it lies from the first one.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

import calippso
from calippso.lp import build_lp, select_pairs
from calippso.geometry.neighbors import NeighborSearch, minimum_image
from calippso.settings import JamSettings
from calippso.solvers.highs import solve

ALPHAS = (1.0, 1.5, 2.0)
COLD_OVER_MEDIAN = 4.0


def growth_along(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                 step: np.ndarray, alphas: tuple[float, ...]) -> list[float]:
    """√Γ − 1 of the configuration `positions + α step` for every α (exact distances).

    Parameters
    ----------
    positions, step : ndarray, shape (N, d)
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    alphas : tuple of float

    Returns
    -------
    list of float
        min over pairs of |r_ij + α s_ij| / σ_ij − 1, for each α.
    """
    reach = float(diameters.max()) + 2.0 * max(alphas) * float(np.linalg.norm(step, axis=1).max())
    pairs = NeighborSearch(positions, diameters, box).pairs_within(reach)
    relative = step[pairs.i] - step[pairs.j]
    return [float(np.min(np.linalg.norm(pairs.vectors + a * relative, axis=1) / pairs.sigma)) - 1.0
            for a in alphas]


def second_order_correction(snapshots: list, box: np.ndarray, n: int, d: int) -> str:
    """Summary of the second-order correction over every LP of the run (see the header)."""
    settings = JamSettings()
    pinned = np.zeros(n, dtype=bool)
    pinned[0] = settings.pin
    overlaps, depths, jumps, count = 0, [], [], 0
    for (x0, sigma0, _), (_, _, record) in zip(snapshots[:-1], snapshots[1:]):
        if record["stage"] != "lp":
            continue
        search = NeighborSearch(x0, sigma0, box)
        lp = build_lp(select_pairs(search, record["step_bound"]), n, d, record["step_bound"],
                      pinned)
        step = solve(lp, settings).x[:-1].reshape(n, d)
        relative = step[lp.pairs.j] - step[lp.pairs.i]
        corrected_rows = dataclasses.replace(lp, row_lower=lp.row_lower - np.einsum(
            "md,md->m", relative, relative) / (2.0 * lp.pairs.distances))
        corrected = solve(corrected_rows, settings).x[:-1].reshape(n, d)
        growth = growth_along(search.positions, sigma0, box, corrected, (1.0,))[0]
        count += 1
        jumps.append(np.abs(corrected - step).max() / record["step_bound"])
        if growth < 0:
            overlaps += 1
            depths.append(-growth)
    depth = f" by {min(depths):.1e} to {max(depths):.1e}" if depths else ""
    return (f"second-order correction: the corrected step overlaps in {overlaps} of {count} "
            f"LPs{depth}; it differs from the LP's step by up to {max(jumps):.2f} of the "
            f"bound (median {np.median(jumps):.2f})")


def ls_input(d: int, n: int, pressure: float, seed: int) -> calippso.Packing:
    """LS from random points to reduced pressure `pressure` (monodisperse; bidisperse 1.4 in
    d = 2), the input of `python bench/jam.py --ls d:n --pressure P --seeds K`."""
    import generators

    sizes = (generators.diameters.bidisperse(n, 1.4, 0.5, seed=seed) if d == 2
             else generators.diameters.monodisperse(n))
    return generators.lubachevsky_stillinger(sizes, d=d, target_pressure=pressure,
                                             seed=seed).packing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--input", help="a packing file for calippso.read (default: our LS)")
    parser.add_argument("--seed", type=int, default=2, help="LS seed (default 2)")
    parser.add_argument("--pressure", type=float, default=1e5, help="LS target pressure")
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--d", type=int, default=3)
    parser.add_argument("--second-order", action="store_true",
                        help="also try a second-order correction on every LP (see the header)")
    args = parser.parse_args()
    start = calippso.read(args.input) if args.input else ls_input(args.d, args.n, args.pressure,
                                                                   args.seed)
    scale = start.mean_diameter
    box = start.box / scale
    snapshots = [(start.positions / scale, start.diameters / scale, None)]

    def keep(record: dict) -> None:
        packing = record["packing"]
        snapshots.append((packing.positions / scale, packing.diameters / scale, record))

    result = calippso.jam(start, callback=keep)
    print(f"{result.status}\n")
    print(f"{'LP':>4} {'max|s|/b':>9} {'cos':>7} {'top5%':>6} "
          + " ".join(f"{'α = ' + format(a, 'g'):>10}" for a in ALPHAS) + "  cold")
    lp_seconds = [r["solver_time"] for _, _, r in snapshots[1:] if r["stage"] == "lp"]
    cold_seconds_above = COLD_OVER_MEDIAN * float(np.median(lp_seconds))
    previous = None
    cold, cold_seconds, warm_seconds = 0, 0.0, 0.0
    for k in range(1, len(snapshots)):
        x0, sigma0, _ = snapshots[k - 1]
        x1, _, record = snapshots[k]
        if record["stage"] != "lp":
            continue
        step = minimum_image(x1 - x0, box)
        cosine = (np.nan if previous is None else
                  float(np.sum(step * previous) / np.linalg.norm(step) / np.linalg.norm(previous)))
        squares = np.sort(np.einsum("nd,nd->n", step, step))
        top = float(squares[-max(1, len(squares) // 20):].sum() / squares.sum())
        growth = growth_along(x0, sigma0, box, step, ALPHAS)
        is_cold = record["solver_time"] > cold_seconds_above
        cold += is_cold
        cold_seconds += record["solver_time"] if is_cold else 0.0
        warm_seconds += 0.0 if is_cold else record["solver_time"]
        print(f"{k:4d} {record['max_displacement'] / record['step_bound']:9.2f} {cosine:7.3f} "
              f"{top:6.2f} " + " ".join(f"{g:10.2e}" for g in growth)
              + f"  {'yes' if is_cold else ''}")
        previous = step
    shift = minimum_image(result.packing.positions - start.positions, start.box) / scale
    moved = np.linalg.norm(shift - shift.mean(axis=0), axis=1)   # without the common translation
    print(f"\nLPs {result.iterations}: {cold} cold ({cold_seconds:.1f} s in the solver), "
          f"the others warm ({warm_seconds:.1f} s); {result.wall_time:.1f} s in all; "
          f"phi {start.phi:.6f} -> {result.packing.phi:.6f}")
    print(f"displacement input -> jammed, common translation removed (mean diameters): "
          f"median {np.median(moved):.2e}, rms {np.sqrt(np.mean(moved**2)):.2e}, max {moved.max():.2e}")
    if args.second_order:
        print(second_order_correction(snapshots, box, start.n, start.d))


if __name__ == "__main__":
    main()
