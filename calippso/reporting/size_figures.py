"""The report's figures across sizes: each exponent against N with its extrapolation, and
the gap distributions collapsed with the cut-off h_min(N)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..analysis.collapse import collapsed_cumulative
from ..analysis.exponents import REFERENCE_EXPONENTS, SYMBOLS
from ..analysis.finite_size import EXPONENT_NAMES, FiniteSizeAnalysis
from ._matplotlib import pyplot
from . import figures
from .figures import thinned

__all__ = ["plot_exponents_vs_n", "plot_gap_collapse"]

#: The extrapolated value is drawn at this multiple of the largest N, marked "N → ∞".
_INFINITY_AT = 30.0
#: Points of the drawn extrapolation curve.
_CURVE_POINTS = 100


def plot_exponents_vs_n(analysis: FiniteSizeAnalysis, path: Path) -> Path:
    """γ, θ_e, θ_ℓ and θ against N with their intervals, the fitted correction continued to
    large N, the limit N → ∞ with its interval and the literature's value."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(10, 7.2), sharex=True)
    largest = max(analysis.sizes)
    for ax, name in zip(axes.ravel(), EXPONENT_NAMES):
        fitted = [s for s in analysis.by_size if name in s.exponents]
        n = np.array([s.n for s in fitted], dtype=np.float64)
        values = np.array([s.exponents[name].value for s in fitted])
        ends = np.array([s.exponents[name].interval for s in fitted]).reshape(-1, 2)
        ax.errorbar(n, values, yerr=[values - ends[:, 0], ends[:, 1] - values], fmt="o",
                    color="k", capsize=3, label="per size (95 % interval)")
        ax.axhline(REFERENCE_EXPONENTS[name], color="C3", ls="--", lw=1.2,
                   label=f"literature {REFERENCE_EXPONENTS[name]:g}")
        limit = analysis.extrapolated.get(name)
        if limit is not None:
            chosen = limit.chosen
            far = _INFINITY_AT * largest
            curve_n = np.geomspace(n.min(), far, _CURVE_POINTS)
            ax.plot(curve_n, chosen(curve_n), "-", color="C0", lw=1.2,
                    label=_form_label(chosen))
            low, high = limit.interval
            ax.errorbar([far], [limit.value], yerr=[[limit.value - low], [high - limit.value]],
                        fmt="s", color="C0", capsize=3,
                        label=f"N → ∞: {limit.value:.3f} [{low:.3f}, {high:.3f}]")
        ax.set_xscale("log")
        ax.set_title(SYMBOLS[name], fontsize=10)
        ax.legend(fontsize=7)
    for ax in axes[1]:
        ax.set_xlabel(f"N (the square at {_INFINITY_AT:g} × the largest N: N → ∞)")
    fig.suptitle(f"exponents against N: d = {analysis.d}, "
                 + ", ".join(f"N = {s.n}: {s.packings}" for s in analysis.by_size)
                 + " packings", fontsize=10)
    return figures._save(fig, path)   # one writer for every report figure


def _form_label(chosen) -> str:
    """The legend of the drawn correction."""
    if chosen.form == "constant":
        return "constant"
    if chosen.form == "inverse_n":
        return "x∞ + a/N"
    return f"x∞ + a N^−ω, ω = {chosen.omega:.2f}" + (" (fitted)" if chosen.omega_fitted else "")


def plot_gap_collapse(analysis: FiniteSizeAnalysis, path: Path) -> Path:
    """Left: Z(h) − z of each size. Middle: the same on the scaled axes h N^(1/(1−γ)) and
    N (Z(h) − z), γ the literature's. Right: h_min(N), the geometric mean of each packing's
    smallest gap, with N^(−1/(1−γ)) through it and the fitted slope."""
    plt = pyplot()
    gamma = REFERENCE_EXPONENTS["gamma"]
    fig, (raw, scaled, cut) = plt.subplots(1, 3, figsize=(14, 4.2))
    for k, size in enumerate(analysis.by_size):
        gaps = size.samples["gamma"]
        color = f"C{k % 10}"
        h, cumulative = thinned(*gaps.cumulative())
        raw.loglog(h, cumulative, color=color, lw=1.2, label=f"N = {size.n} ({size.packings})")
        x, y = thinned(*collapsed_cumulative(gaps, size.n, gamma))
        scaled.loglog(x, y, color=color, lw=1.2, label=f"N = {size.n}")
    raw.set_xlabel("h")
    raw.set_ylabel("Z(h) − z")
    raw.legend(fontsize=7)
    scaled.set_xlabel(f"h N^(1/(1−γ)), γ = {gamma:g}")
    scaled.set_ylabel("N (Z(h) − z)")
    scaled.legend(fontsize=7)
    cutoff = analysis.gap_cutoff
    errors = np.abs(cutoff.interval - cutoff.h_min[:, None]).T
    cut.errorbar(cutoff.sizes, cutoff.h_min, yerr=errors, fmt="o", color="k", capsize=3,
                 label="h_min(N), geometric mean")
    line_n = np.geomspace(cutoff.sizes.min(), cutoff.sizes.max(), _CURVE_POINTS)
    cut.loglog(line_n, cutoff.scaling_line(line_n, gamma), "--", color="C3",
               label=f"N^(−1/(1−γ)), γ = {gamma:g}")
    if np.isfinite(cutoff.gamma):
        low, high = cutoff.gamma_interval
        cut.loglog(line_n, cutoff.scaling_line(line_n, cutoff.gamma), "-", color="C0",
                   label=f"fit: γ = {cutoff.gamma:.3f} [{low:.3f}, {high:.3f}]")
    cut.set_xlabel("N")
    cut.set_ylabel("smallest gap of a packing")
    cut.legend(fontsize=7)
    fig.suptitle(f"gap distribution across sizes, d = {analysis.d}", fontsize=10)
    return figures._save(fig, path)   # one writer for every report figure
