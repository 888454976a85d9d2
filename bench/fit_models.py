"""Bias and spread of the exponent fits on synthetic samples: pure power law against cut-off.

Each density is a power law f^θ only as f → 0, with a correction of first or second order, and
mean near 1 (the scale of forces normalised by their mean):

* gamma:      f^θ e^(−(1 + θ) f)           (first-order correction, exactly the cut-off model)
* rational:   f^θ / (1 + f)^3              (first-order correction, not exponential)
* gaussian:   f^θ e^(−f²)                  (second-order correction only)
* pure:       f^θ on [0, 1]                (no correction: what the pure model assumes)

For each density, window top and sample size, `--repeats` independent samples are drawn and
fitted by maximum likelihood (window from the 10th smallest value to the top) with the pure
power law, with the cut-off model, and with model "auto" (the likelihood-ratio choice); the
table gives mean − θ and the standard deviation of θ over the samples, and how often "auto"
chose the cut-off. Run from the repository root:

    python bench/fit_models.py                        # θ = 0.42311, 102 000 and 20 400 values
    python bench/fit_models.py --theta 0.17 --sizes 20000 --repeats 50
"""

from __future__ import annotations

import argparse

import numpy as np

from calippso.analysis.fits import fit_cumulative_power_law


def draw(density: str, theta: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """`n` values from `density` (see the module notes)."""
    if density == "gamma":
        return rng.gamma(1.0 + theta, 1.0 / (1.0 + theta), n)
    if density == "pure":
        return rng.random(n) ** (1.0 / (1.0 + theta))
    correction = {"rational": lambda f: (1.0 + f) ** -3.0,
                  "gaussian": lambda f: np.exp(-f ** 2)}[density]
    kept: list[np.ndarray] = []
    while sum(part.size for part in kept) < n:       # rejection from f^θ on [0, 4]
        f = 4.0 * rng.random(4 * n) ** (1.0 / (1.0 + theta))
        kept.append(f[rng.random(f.size) < correction(f)])
    return np.concatenate(kept)[:n]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--theta", type=float, default=0.42311)
    parser.add_argument("--sizes", type=int, nargs="+", default=[102000, 20400],
                        help="values per sample (default: 34 packings × 3000 and × 600)")
    parser.add_argument("--tops", type=float, nargs="+", default=[0.1, 0.3, 1.0])
    parser.add_argument("--densities", nargs="+", default=["gamma", "rational", "gaussian",
                                                           "pure"])
    parser.add_argument("--repeats", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"θ = {args.theta}; {args.repeats} samples per row; mean − θ ± standard deviation")
    print(f"{'density':>9} {'values':>7} {'top':>5} {'in window':>9} | {'power law':>15} "
          f"{'cut-off':>15} {'auto':>15} {'auto: cut-off':>13}")
    for density in args.densities:
        for n in args.sizes:
            for top in args.tops:
                found = {"power_law": [], "cutoff": [], "auto": []}
                chose_cutoff, points = 0, 0
                for _ in range(args.repeats):
                    sample = draw(density, args.theta, n, rng)
                    for model in found:
                        fit = fit_cumulative_power_law(sample, top, model=model, n_bootstrap=0)
                        found[model].append(fit.slope - 1.0 - args.theta)
                    chose_cutoff += fit.model == "cutoff"
                    points += fit.n_points
                cells = " ".join(f"{np.mean(v):+7.3f} ± {np.std(v):5.3f}"
                                 for v in found.values())
                print(f"{density:>9} {n:7d} {top:5.2g} {points // args.repeats:9d} | {cells} "
                      f"{chose_cutoff / args.repeats:12.0%}")


if __name__ == "__main__":
    main()
