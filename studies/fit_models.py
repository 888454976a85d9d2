"""Bias and spread of the exponent fits on synthetic samples: pure power law against cut-off.

Each density is a power law f^θ only as f → 0, with a correction of first or second order, and
mean near 1 (the scale of forces normalised by their mean):

* gamma:      f^θ e^(−(1 + θ) f)           (first-order correction, exactly the cut-off model)
* rational:   f^θ / (1 + f)^3              (first-order correction, not exponential)
* gaussian:   f^θ e^(−f²)                  (second-order correction only)
* pure:       f^θ on [0, 1]                (no correction: what the pure model assumes)

With ``--gaps`` the samples are gap-like instead, densities h^−γ on [0, 0.1] (γ = `--theta`,
default then 0.41269), fitted over h ≤ `--tops` (default 1e-2), exponent γ = 1 − slope:

* depleted-<h0>: h^−γ (1 − e^(−√(h/h0))), a finite-size depletion of the smallest gaps,
  for h0 = 1e-6, 1e-5, 1e-4;
* background-<h*>: h^−γ (1 + (h/h*)^γ), a constant background B = h*^−γ, h* = 0.01, 0.05, 0.2.

For each density, window top and sample size, `--repeats` independent samples are drawn and
fitted by maximum likelihood (window from the 10th smallest value to the top) with the pure
power law, with the cut-off model, and with model "auto" (the likelihood-ratio choice); the
table gives mean − θ and the standard deviation of θ over the samples, and how often "auto"
chose the cut-off. Run from the repository root:

    python studies/fit_models.py                        # θ = 0.42311, 102 000 and 20 400 values
    python studies/fit_models.py --theta 0.17 --sizes 20000 --repeats 50
    python studies/fit_models.py --gaps --sizes 49000 --repeats 40
    python studies/fit_models.py --coverage 200 --densities gamma --sizes 100000 --tops 0.3 \
        --repeats 40

With ``--coverage K`` each sample is instead fitted with the cut-off model and K bootstrap
resamples, and the table gives, per row, how often the 95 % interval covers the exponent and
the mean interval width / 3.92 against the spread of the estimate (equal when the interval is
calibrated).
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


def draw_gaps(density: str, gamma: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """`n` gap-like values from "depleted-<h0>" or "background-<h*>" on [0, 0.1]."""
    kind, scale = density.split("-", 1)
    scale = float(scale)
    kept: list[np.ndarray] = []
    while sum(part.size for part in kept) < n:       # rejection from h^−γ on [0, 0.1]
        h = 0.1 * rng.random(4 * n) ** (1.0 / (1.0 - gamma))
        if kind == "depleted":
            accept = 1.0 - np.exp(-np.sqrt(h / scale))
        else:
            accept = (1.0 + (h / scale) ** gamma) / (1.0 + (0.1 / scale) ** gamma)
        kept.append(h[rng.random(h.size) < accept])
    return np.concatenate(kept)[:n]


def coverage(args: argparse.Namespace, densities: list[str], tops: list[float], theta: float,
             rng: np.random.Generator) -> None:
    """Coverage and width of the bootstrap interval of the cut-off fit (see the notes)."""
    print(f"exponent {theta}; {args.repeats} samples per row, {args.coverage} resamples each; "
          "cut-off model")
    print(f"{'density':>16} {'values':>7} {'top':>5} | {'covered':>8} {'width/3.92':>10} "
          f"{'spread':>7}")
    for density in densities:
        for n in args.sizes:
            for top in tops:
                estimates, widths, covered = [], [], 0
                for k in range(args.repeats):
                    sample = (draw_gaps if args.gaps else draw)(density, theta, n, rng)
                    fit = fit_cumulative_power_law(sample, top, model="cutoff",
                                                   n_bootstrap=args.coverage, seed=k)
                    ends = sorted((1.0 - e if args.gaps else e - 1.0) for e in fit.interval)
                    estimates.append(1.0 - fit.slope if args.gaps else fit.slope - 1.0)
                    widths.append(ends[1] - ends[0])
                    covered += ends[0] < theta < ends[1]
                print(f"{density:>16} {n:7d} {top:5.2g} | {covered:3d} / {args.repeats:<3d} "
                      f"{np.mean(widths) / 3.92:10.4f} {np.std(estimates):7.4f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gaps", action="store_true", help="gap-like samples (see above)")
    parser.add_argument("--theta", type=float, default=None,
                        help="exponent (default 0.42311, or γ = 0.41269 with --gaps)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[102000, 20400],
                        help="values per sample (default: 34 packings × 3000 and × 600)")
    parser.add_argument("--tops", type=float, nargs="+", default=None,
                        help="window tops (default 0.1 0.3 1, or 0.01 with --gaps)")
    parser.add_argument("--densities", nargs="+", default=None)
    parser.add_argument("--repeats", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--coverage", type=int, default=0, metavar="K",
                        help="check the bootstrap interval of the cut-off fit, K resamples")
    args = parser.parse_args()
    if args.gaps:
        theta = 0.41269 if args.theta is None else args.theta
        tops = args.tops or [1e-2]
        densities = args.densities or ["depleted-1e-6", "depleted-1e-5", "depleted-1e-4",
                                       "background-0.01", "background-0.05", "background-0.2"]
    else:
        theta = 0.42311 if args.theta is None else args.theta
        tops = args.tops or [0.1, 0.3, 1.0]
        densities = args.densities or ["gamma", "rational", "gaussian", "pure"]
    rng = np.random.default_rng(args.seed)
    if args.coverage:
        coverage(args, densities, tops, theta, rng)
        return
    print(f"exponent {theta}; {args.repeats} samples per row; mean − exponent ± standard "
          "deviation")
    print(f"{'density':>16} {'values':>7} {'top':>5} {'in window':>9} | {'power law':>15} "
          f"{'cut-off':>15} {'auto':>15} {'auto: cut-off':>13}")
    for density in densities:
        for n in args.sizes:
            for top in tops:
                found = {"power_law": [], "cutoff": [], "auto": []}
                chose_cutoff, points = 0, 0
                for _ in range(args.repeats):
                    sample = (draw_gaps if args.gaps else draw)(density, theta, n, rng)
                    for model in found:
                        fit = fit_cumulative_power_law(sample, top, model=model, n_bootstrap=0)
                        exponent = 1.0 - fit.slope if args.gaps else fit.slope - 1.0
                        found[model].append(exponent - theta)
                    chose_cutoff += fit.model == "cutoff"
                    points += fit.n_points
                cells = " ".join(f"{np.mean(v):+7.3f} ± {np.std(v):5.3f}"
                                 for v in found.values())
                print(f"{density:>16} {n:7d} {top:5.2g} {points // args.repeats:9d} | {cells} "
                      f"{chose_cutoff / args.repeats:12.0%}")


if __name__ == "__main__":
    main()
