"""Coverage of the extrapolation N → ∞ on synthetic finite-size trends, by way of choosing
the correction form.

Draws x(N) = x_∞ + a N^(−ω) + noise (normal, σ per size, the interval ±1.96 σ) at the sizes
given, for several planted (a, ω), and extrapolates each sample with
`calippso.analysis.extrapolate`:

* ``fitted omega``: ``form="auto"`` (ω fitted from four sizes on);
* ``lowest AICc``: the candidate form with the lowest small-sample Akaike criterion, then
  its interval;
* ``1/N``: ``form="inverse_n"``.

Prints, per trend and way: how often the 95 % interval holds x_∞, the mean width and the
mean error. ``python bench/extrapolation_coverage.py --sizes 1024 2048 4096 8192 --sigma
0.005 --samples 100`` (about a minute; ``--json PATH`` keeps the rows).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from calippso.analysis import extrapolate

#: Planted trends: (label, a, ω); x_∞ = `LIMIT`.
TRENDS = (("none", 0.0, 1.0), ("a/N, a = −20", -20.0, 1.0),
          ("a N^−0.5, a = −0.8", -0.8, 0.5), ("a N^−0.3, a = −0.3", -0.3, 0.3))
LIMIT = 0.41269
#: Draws of the parametric bootstrap per extrapolation.
DRAWS = 400


def one_sample(n, x, intervals, seed: int) -> dict[str, tuple[float, float, float]]:
    """(low, high, value) of x_∞ by each way of choosing the form."""
    rows = {}
    auto = extrapolate(n, x, intervals, n_draws=DRAWS, seed=seed)
    rows["fitted omega"] = (*auto.interval, auto.value)
    ranked = [c for c in auto.candidates.values() if math.isfinite(c.aicc)]
    best = min(ranked, key=lambda c: c.aicc).form
    chosen = extrapolate(n, x, intervals, form=best, n_draws=DRAWS, seed=seed)
    rows["lowest AICc"] = (*chosen.interval, chosen.value)
    inverse = extrapolate(n, x, intervals, form="inverse_n", n_draws=DRAWS, seed=seed)
    rows["1/N"] = (*inverse.interval, inverse.value)
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1024, 2048, 4096, 8192])
    parser.add_argument("--sigma", type=float, default=0.005)
    parser.add_argument("--samples", type=int, default=100)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    n = np.array(args.sizes, dtype=np.float64)
    rng = np.random.default_rng(args.seed)
    rows = []
    print(f"sizes {args.sizes}, σ = {args.sigma:g}, {args.samples} samples per trend")
    print("| trend | way | covered | mean width | mean error |")
    print("|---|---|---|---|---|")
    for label, amplitude, omega in TRENDS:
        tally: dict[str, list[tuple[float, float, float]]] = {}
        for k in range(args.samples):
            x = LIMIT + amplitude * n ** -omega + rng.normal(0.0, args.sigma, n.size)
            intervals = np.c_[x - 1.96 * args.sigma, x + 1.96 * args.sigma]
            for way, result in one_sample(n, x, intervals, seed=k).items():
                tally.setdefault(way, []).append(result)
        for way, results in tally.items():
            low, high, value = np.array(results).T
            row = {"trend": label, "way": way, "sizes": args.sizes, "sigma": args.sigma,
                   "samples": args.samples,
                   "covered": float(np.mean((low < LIMIT) & (LIMIT < high))),
                   "mean_width": float(np.mean(high - low)),
                   "mean_error": float(np.mean(value - LIMIT))}
            rows.append(row)
            print(f"| {label} | {way} | {100 * row['covered']:.0f} % | "
                  f"{row['mean_width']:.3f} | {row['mean_error']:+.4f} |", flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
