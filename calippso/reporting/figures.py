"""The report's figures: cumulative force and gap distributions with their fits, the
contact-number histogram, the error of one run against wall time, and for packings with walls
the wall forces and the layering profile. Each function writes one PNG and returns its path."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..analysis import Analysis
from ..analysis.exponents import REFERENCE_EXPONENTS, Exponent
from ..analysis.sample import PooledSample
from ..result import JammingResult
from ._matplotlib import pyplot

__all__ = ["plot_forces", "plot_gaps", "plot_contact_numbers", "plot_history", "plot_walls",
           "thinned"]

_DPI = 120
#: Smallest value drawn on a log axis (an exact zero is drawn there).
_LOG_FLOOR = 1e-17
#: Contact-number histogram: room above the tallest bar for the labels (factor), the colour
#: and width (points) of the band at 2d, and how far (contacts) a label sits from its line.
_HEADROOM = 1.18
_ISOSTATIC_COLOUR = "C1"
_ISOSTATIC_WIDTH = 7.0
_LABEL_OFFSET = 0.12
#: Wall-force histogram: number of bins over [0, the largest force].
_WALL_FORCE_BINS = 20
#: Most points drawn of one cumulative: beyond it the points are taken at log-spaced ranks
#: (a line through millions of values looks the same and takes seconds to draw).
MAX_DRAWN_POINTS = 4000


def _save(fig, path: Path) -> Path:
    """Lay out `fig`, write it to `path` as PNG, close it; returns `path`."""
    fig.tight_layout()
    fig.savefig(path, dpi=_DPI)
    pyplot().close(fig)
    return path


def _fit_and_reference(ax, exponent: Exponent, slope_of_reference: float, color: str,
                       label: str) -> None:
    """The fitted cumulative over its window, and the reference slope through its upper end."""
    fit = exponent.fit
    x = np.geomspace(fit.lower, fit.upper, 50)
    low, high = exponent.interval
    model = ", with cut-off" if fit.model == "cutoff" else ""
    ax.plot(x, fit(x), "-", color=color, lw=2.2, alpha=0.8,
            label=f"fit {label} = {exponent.value:.3f} [{low:.3f}, {high:.3f}]{model}")
    anchor = fit(fit.upper)
    x_ref = np.geomspace(fit.lower / 10, fit.upper, 50)
    ax.plot(x_ref, anchor * (x_ref / fit.upper) ** slope_of_reference, ":", color=color, lw=1.5,
            label=f"reference {label} = {REFERENCE_EXPONENTS[exponent.name]:g}")


def thinned(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At most `MAX_DRAWN_POINTS` of the points (x_k, y_k), at log-spaced ranks k (the first
    and the last kept), for drawing a cumulative on log axes."""
    if x.size <= MAX_DRAWN_POINTS:
        return x, y
    ranks = np.unique(np.geomspace(1, x.size, MAX_DRAWN_POINTS).astype(np.int64) - 1)
    return x[ranks], y[ranks]


def _cumulative(ax, sample: PooledSample, **style) -> None:
    x, c = thinned(*sample.cumulative())
    keep = x > 0
    if keep.any():
        ax.loglog(x[keep], c[keep], **style)


def plot_forces(analysis: Analysis, path: Path) -> Path:
    """Log-log cumulative distributions G(f) of all, extended and localised forces."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    styles = {"all": ("0.6", "all"), "extended": ("C0", "extended"),
              "localized": ("C3", f"localised (rule {analysis.rule})")}
    for kind, (color, label) in styles.items():
        sample = analysis.forces[kind]
        _cumulative(ax, sample, color=color, lw=1.2, label=f"{label} ({len(sample)})")
    for name, color, label in (("theta", "0.4", "θ"), ("theta_e", "C0", "θ_e"),
                               ("theta_l", "C3", "θ_ℓ")):
        if name in analysis.exponents:
            _fit_and_reference(ax, analysis.exponents[name], 1 + REFERENCE_EXPONENTS[name],
                               color, label)
    ax.set_xlabel("f / ⟨f⟩  (particle–particle contacts; wall forces apart)")
    ax.set_ylabel("G(f)  (cumulative distribution)")
    ax.set_title(_title(analysis, "forces"))
    ax.legend(fontsize=7, loc="lower right")
    return _save(fig, path)


def plot_gaps(analysis: Analysis, path: Path) -> Path:
    """Z(h) − z (non-contact neighbours within gap h per stable particle) and g(h), log-log."""
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.2))
    _cumulative(left, analysis.gaps, color="k", lw=1.2, label=f"{len(analysis.gaps)} gaps")
    if "gamma" in analysis.exponents:
        _fit_and_reference(left, analysis.exponents["gamma"], 1 - REFERENCE_EXPONENTS["gamma"],
                           "C2", "γ")
    left.set_xlabel("h = r/σ − 1")
    left.set_ylabel("Z(h) − z  (cumulative, per stable particle)")
    left.legend(fontsize=7, loc="lower right")
    centres, density = analysis.gaps.density(bins_per_decade=4)
    right.loglog(centres, density, "o", color="k", ms=4, label="g(h) = dZ/dh")
    if centres.size:
        ref = density[-1] * (centres / centres[-1]) ** (-REFERENCE_EXPONENTS["gamma"])
        right.loglog(centres, ref, ":", color="C2",
                     label=f"h^−γ, γ = {REFERENCE_EXPONENTS['gamma']:g}")
    right.set_xlabel("h")
    right.set_ylabel("g(h)")
    right.legend(fontsize=7)
    fig.suptitle(_title(analysis, "gaps"), fontsize=10)
    return _save(fig, path)


def plot_contact_numbers(analysis: Analysis, path: Path) -> Path:
    """Histogram of the contact numbers of stable particles, with the mean z and the
    isostatic value 2d marked.

    The two marks nearly coincide in a jammed packing (z = 2d − O(1/N)): 2d is a wide pale
    band under the thin mean-z line, so both show, each labelled on its own side.
    """
    plt = pyplot()
    stats = analysis.contacts
    z, fraction = stats.histogram()
    fig, ax = plt.subplots(figsize=(5.2, 3.8))
    colors = ["C3" if value == stats.d + 1 else "C0" for value in z]
    ax.bar(z, fraction, color=colors, width=0.8, zorder=1)
    ax.set_ylim(0, _HEADROOM * max(fraction.max(), 1e-12))
    isostatic = 2 * stats.d
    ax.axvline(isostatic, color=_ISOSTATIC_COLOUR, lw=_ISOSTATIC_WIDTH, alpha=0.45, zorder=2)
    ax.axvline(stats.mean_z, color="k", ls="--", lw=1.2, zorder=3)
    mean_left = stats.mean_z <= isostatic
    _side_label(ax, isostatic, f"2d = {isostatic}", left=not mean_left,
                color=_ISOSTATIC_COLOUR)
    _side_label(ax, stats.mean_z, f"mean z = {stats.mean_z:.4f}", left=mean_left, color="k")
    ax.set_xlabel("contacts per stable particle (red: bucklers, d + 1)")
    ax.set_ylabel("fraction of stable particles")
    ax.set_title(_title(analysis, "contact numbers"))
    return _save(fig, path)


def _side_label(ax, x: float, text: str, left: bool, color: str) -> None:
    """`text` near the top of the vertical line at `x`, beside it on the left or right."""
    from matplotlib.transforms import blended_transform_factory

    offset = -_LABEL_OFFSET if left else _LABEL_OFFSET
    ax.text(x + offset, 0.97, text, transform=blended_transform_factory(ax.transData,
                                                                       ax.transAxes),
            ha="right" if left else "left", va="top", fontsize=8, color=color, zorder=4)


def plot_history(result: JammingResult, path: Path, title: str = "") -> Path:
    """√Γ − 1, max|s|, |isostaticity gap| and force balance of one run against wall time."""
    plt = pyplot()
    history = result.history
    if history.shape[0] == 0:
        raise ValueError("the result has no history to plot")
    t = history["wall_time"]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 5.6), sharex=True,
                                      gridspec_kw={"height_ratios": [2, 1]})
    for column, label, marker in (("sqrt_gamma_minus_1", "√Γ − 1", "o"),
                                  ("max_displacement", "max |s| (mean diameters)", "s"),
                                  ("force_balance", "force balance", "^")):
        values = np.maximum(np.abs(history[column]), _LOG_FLOOR)
        top.semilogy(t, values, marker=marker, ms=3, lw=1, label=label)
    top.axhline(_LOG_FLOOR, color="0.8", lw=0.8)
    top.set_ylabel(f"error (0 drawn at {_LOG_FLOOR:g})")
    top.legend(fontsize=8)
    bottom.plot(t, np.abs(history["isostaticity_gap"]), "o-", ms=3, lw=1, color="C3")
    bottom.set_yscale("symlog", linthresh=1)
    bottom.set_ylabel("|N_c − d(N_s − 1) − 1|")
    bottom.set_xlabel("wall time (s, cumulative)")
    top.set_title(title or f"N = {result.packing.n}, d = {result.d}, {result.solver}: "
                  f"{result.iterations} LPs, {result.wall_time:.1f} s", fontsize=10)
    return _save(fig, path)


def plot_walls(analysis: Analysis, path: Path) -> Path:
    """Left: the distribution of the wall forces beside that of the particle–particle
    forces (both in units of the mean particle–particle force of their packing). Right: the
    layering profile, packing fraction against the distance from the nearest wall, with the
    packing fraction of the whole packing.

    Raises
    ------
    ValueError
        No packing of the analysis has walls.
    """
    if analysis.layering is None or analysis.wall_forces is None:
        raise ValueError("no packing of this analysis has walls")
    plt = pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.2))
    pair, wall = analysis.forces["all"].values, analysis.wall_forces.values
    largest = max(float(pair.max()) if pair.size else 1.0,
                  float(wall.max()) if wall.size else 1.0)
    edges = np.linspace(0.0, largest, _WALL_FORCE_BINS + 1)
    left.hist(pair, bins=edges, density=True, color="0.6", alpha=0.7,
              label=f"particle–particle ({pair.size})")
    if wall.size:
        left.hist(wall, bins=edges, density=True, histtype="step", color="C3", lw=1.8,
                  label=f"wall ({wall.size})")
    left.set_xlabel("f / ⟨f⟩ (mean particle–particle force)")
    left.set_ylabel("P(f)")
    left.legend(fontsize=8)
    profile = analysis.layering
    right.plot(profile.distance, profile.phi, "-", color="k", lw=1.2, label="φ(s)")
    right.axhline(float(np.mean(analysis.contacts.phi)), color="C1", ls="--", lw=1.2,
                  label="φ of the packing")
    right.set_xlabel("s, distance from the nearest wall (mean diameters)")
    right.set_ylabel("local packing fraction φ(s)")
    right.set_xlim(0.0, float(profile.distance[-1]))
    right.legend(fontsize=8)
    fig.suptitle(_title(analysis, "walls"), fontsize=10)
    return _save(fig, path)


def _title(analysis: Analysis, what: str) -> str:
    stats = analysis.contacts
    return (f"{what}: d = {stats.d}, {stats.n_packings} packing"
            f"{'s' if stats.n_packings != 1 else ''}, {stats.n_particles} particles")
