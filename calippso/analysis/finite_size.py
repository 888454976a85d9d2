"""The critical exponents at each size N and their extrapolation to N → ∞.

`finite_size_analysis` groups packings by their number of particles, fits γ, θ_e, θ_ℓ and θ
at each size with the same windows, models and bootstrap as the pooled fit
(`calippso.analysis.exponents`), and extrapolates each exponent to N → ∞
(`calippso.analysis.extrapolation`: x(N) = x_∞ + a N^(−ω) with ω fitted from four sizes on,
1/N with fewer, or a form asked for). Beside them it measures the cut-off of the gap
distribution, h_min(N) against N^(−1/(1−γ)) (`calippso.analysis.collapse`).
`packings_needed` says how many packings bring an interval to a given half-width.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from ..result import JammingResult
from ._inputs import as_results
from .collapse import GapCutoff, gap_cutoff
from .exponents import UPPER, Exponent, exponent_from_sample, resolve_models
from .extrapolation import Extrapolation, extrapolate
from .forces import DEFAULT_RULE, canonical_rule, split_forces
from .gaps import DEFAULT_MAX_GAP, pooled_gaps
from .sample import PooledSample

__all__ = ["EXPONENT_NAMES", "GAP_FLOORS", "FiniteSizeAnalysis", "SizeExponents", "exponent_samples",
           "finite_size_analysis", "packings_needed", "sizes_of"]

#: Slack below an integer count of packings that round-off must not push to the next one.
_ROUND_OFF = 1e-9
#: Where the γ window of each size may start (`finite_size_analysis`).
GAP_FLOORS = ("rank", "cutoff")
#: The exponents fitted at each size, in report order.
EXPONENT_NAMES = ("gamma", "theta_e", "theta_l", "theta")


@dataclass(frozen=True)
class SizeExponents:
    """The exponents of the packings of one size.

    Attributes
    ----------
    n : int
        Particles per packing.
    packings : int
    exponents : dict of str to Exponent
        Those that could be fitted.
    errors : dict of str to str
        Why the others could not.
    samples : dict of str to PooledSample
        The pooled gaps ("gamma") and forces of this size.
    """

    n: int
    packings: int
    exponents: dict[str, Exponent]
    errors: dict[str, str]
    samples: dict[str, PooledSample] = field(repr=False, default_factory=dict)

    def to_dict(self) -> dict:
        """{"packings": …, name: {"value", "interval"} …} (None for an exponent not fitted)."""
        return {"packings": self.packings, **{
            name: ({"value": e.value, "interval": list(e.interval),
                    "window": [e.fit.lower, e.fit.upper], "points_in_window": e.fit.n_points,
                    "model": e.fit.model}
                   if (e := self.exponents.get(name)) is not None else None)
            for name in EXPONENT_NAMES}}


@dataclass(frozen=True)
class FiniteSizeAnalysis:
    """Exponents per size, their limits N → ∞ and the gap cut-off.

    Attributes
    ----------
    d : int
    by_size : tuple of SizeExponents
        Ascending in N.
    extrapolated : dict of str to Extrapolation
        Per exponent fitted at two sizes or more.
    extrapolation_errors : dict of str to str
        Why an exponent has no extrapolation.
    gap_cutoff : GapCutoff
    gap_floor : str
        Where the γ window of each size started ("rank" or "cutoff").
    """

    d: int
    by_size: tuple[SizeExponents, ...]
    extrapolated: dict[str, Extrapolation]
    extrapolation_errors: dict[str, str]
    gap_cutoff: GapCutoff
    gap_floor: str = "rank"

    @property
    def sizes(self) -> tuple[int, ...]:
        """N of each size, ascending."""
        return tuple(s.n for s in self.by_size)

    def to_dict(self) -> dict:
        """The report's "by_size", "extrapolated" and "gap_cutoff" entries (JSON-ready)."""
        return {"by_size": {str(s.n): s.to_dict() for s in self.by_size},
                "extrapolated": {name: e.to_dict() for name, e in self.extrapolated.items()},
                "extrapolation_errors": dict(self.extrapolation_errors),
                "gap_cutoff": self.gap_cutoff.to_dict(), "gap_floor": self.gap_floor}


def sizes_of(results: JammingResult | Iterable[JammingResult]) -> np.ndarray:
    """The number of particles of each packing, shape (P,), int64."""
    return np.array([r.packing.n for r in as_results(results)], dtype=np.int64)


def exponent_samples(results: JammingResult | Iterable[JammingResult], *,
                     max_gap: float = DEFAULT_MAX_GAP,
                     rule: str = DEFAULT_RULE) -> dict[str, PooledSample]:
    """The pooled sample behind each exponent: gaps for "gamma", the extended, localised and
    all forces for "theta_e", "theta_l", "theta" (one group per packing, in order)."""
    items = as_results(results)
    forces = split_forces(items, canonical_rule(rule))
    return {"gamma": pooled_gaps(items, max_gap), "theta_e": forces["extended"],
            "theta_l": forces["localized"], "theta": forces["all"]}


def finite_size_analysis(results: JammingResult | Iterable[JammingResult], *,
                         max_gap: float = DEFAULT_MAX_GAP, rule: str = DEFAULT_RULE,
                         upper: dict[str, float] | None = None,
                         model: str | dict[str, str] | None = None, form: str = "auto",
                         omega: float | None = None, gap_floor: str = "rank",
                         samples: dict[str, PooledSample] | None = None,
                         **fit_options) -> FiniteSizeAnalysis:
    """Fit the exponents at each size and extrapolate them to N → ∞.

    Parameters
    ----------
    results : iterable of JammingResult
        Packings of one dimension and at least two sizes, in any order.
    max_gap, rule, upper, model
        As in `calippso.analysis.analyze`.
    form : {"auto", "constant", "inverse_n", "power"}
        Correction form of the extrapolation (`calippso.analysis.extrapolation`).
    omega : float, optional
        Fix ω of the form "power".
    gap_floor : {"rank", "cutoff"}
        Where the γ window of each size starts: at the 10th smallest pooled gap (the window
        rule of `calippso.analysis.fits`, "rank"), or at that size's cut-off h_min(N), the
        geometric mean of each packing's smallest gap ("cutoff"), above the finite-size
        depletion of the smallest gaps.
    samples : dict, optional
        The pooled samples of `exponent_samples` for these results (one group per
        packing, in the order of `results`), when already computed.
    **fit_options
        Passed to `fit_cumulative_power_law` (min_count, method, n_bootstrap, confidence,
        seed); the extrapolation uses the same confidence and seed.

    Returns
    -------
    FiniteSizeAnalysis

    Raises
    ------
    ValueError
        All packings of one size, or packings of several dimensions.
    """
    if gap_floor not in GAP_FLOORS:
        raise ValueError(f"gap_floor must be one of {GAP_FLOORS}, got {gap_floor!r}")
    items = as_results(results)
    n_of = sizes_of(items)
    sizes = np.unique(n_of)
    if sizes.size < 2:
        raise ValueError(f"a finite-size analysis needs packings of two sizes or more, all "
                         f"{items[0].packing.n} here")
    samples = samples or exponent_samples(items, max_gap=max_gap, rule=rule)
    uppers = {**UPPER, **(upper or {})}
    models = resolve_models(model)
    own_samples = {int(n): {name: samples[name].select(np.flatnonzero(n_of == n))
                            for name in EXPONENT_NAMES} for n in sizes}
    cutoff = gap_cutoff({n: own["gamma"] for n, own in own_samples.items()},
                        fit_options.get("confidence", 0.95))
    by_size = []
    for k, (n, own) in enumerate(own_samples.items()):
        exponents, errors = {}, {}
        for name in EXPONENT_NAMES:
            floor = ({"lower": float(cutoff.h_min[k])}
                     if name == "gamma" and gap_floor == "cutoff"
                     and np.isfinite(cutoff.h_min[k]) else {})
            try:
                exponents[name] = exponent_from_sample(name, own[name], upper=uppers[name],
                                                       model=models[name], **floor,
                                                       **fit_options)
            except ValueError as error:
                errors[name] = str(error)
        by_size.append(SizeExponents(n, own["gamma"].n_groups, exponents, errors, own))
    extrapolated, failures = {}, {}
    options = {k: fit_options[k] for k in ("confidence", "seed") if k in fit_options}
    for name in EXPONENT_NAMES:
        fitted = [s for s in by_size if name in s.exponents]
        try:
            extrapolated[name] = extrapolate(
                [s.n for s in fitted], [s.exponents[name].value for s in fitted],
                [s.exponents[name].interval for s in fitted], form=form, omega=omega,
                **options)
        except ValueError as error:
            failures[name] = str(error)
    return FiniteSizeAnalysis(d=items[0].d, by_size=tuple(by_size), extrapolated=extrapolated,
                              extrapolation_errors=failures, gap_cutoff=cutoff,
                              gap_floor=gap_floor)


def packings_needed(interval: tuple[float, float], packings: int, half_width: float) -> int:
    """Packings that bring an interval to ± `half_width`, from one measured on `packings`.

    The width of a bootstrap interval over whole packings falls as 1/√packings, so
    `packings` × (measured half-width / `half_width`)², rounded up.

    Parameters
    ----------
    interval : tuple of float
        (low, high), measured on `packings` packings.
    packings : int
    half_width : float
        The half-width wanted (> 0).
    """
    if not half_width > 0 or packings < 1:
        raise ValueError("half_width must be positive and packings at least 1")
    measured = 0.5 * (interval[1] - interval[0])
    return int(math.ceil(packings * (measured / half_width) ** 2 - _ROUND_OFF))
