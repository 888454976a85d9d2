"""Critical exponents γ, θ_e, θ_ℓ and θ from pooled gaps and forces, with reference values.

Each exponent comes from a power-law fit of a cumulative (`calippso.analysis.fits`):

=======  ==========================  ===================  ===============  =========
name     distribution                cumulative           exponent         reference
=======  ==========================  ===================  ===============  =========
gamma    g(h) ~ h^−γ (gaps)          Z(h) − z ~ h^(1−γ)   γ = 1 − slope    0.41269
theta_e  P_e(f) ~ f^θ_e (extended)   G_e(f) ~ f^(1+θ_e)   θ_e = slope − 1  0.42311
theta_l  P_ℓ(f) ~ f^θ_ℓ (localised)  G_ℓ(f) ~ f^(1+θ_ℓ)   θ_ℓ = slope − 1  0.17
theta    P(f) ~ f^θ (all forces)     G(f) ~ f^(1+θ)       θ = slope − 1    0.17
=======  ==========================  ===================  ===============  =========

θ is the weak-force exponent of all contacts together, the one most papers report. At small
f the two kinds add up, P(f) ≈ P_ℓ(f) + P_e(f), so θ = min(θ_ℓ, θ_e) = θ_ℓ asymptotically
(Lerner, Düring & Wyart 2013): its reference is θ_ℓ. It does not depend on the localisation
rule.

Upper ends of the fit windows (`UPPER`): h ≤ 1e-2 for gaps, f ≤ 0.3 (mean force 1) for
forces. Below the gap top the local slope of the pooled d = 3 gap cumulative is steady; at
the force top the model chosen by the likelihood-ratio test (`calippso.analysis.fits`, model
"auto") recovers the exponent of synthetic force samples with a first- or second-order
correction (docs/notes/fit-models.md).

Models (`MODEL`, `calippso.analysis.fits`): the forces are fitted with model "auto", a pure
power law unless the likelihood-ratio test rejects it for a power law with exponential
cut-off, whose exponent is that of the f → 0 limit; the gaps with the pure power law. The
cut-off absorbs a correction at the top of the window, of order x / (scale of the
distribution): for forces the window top 0.3 is a third of the mean force, for gaps the top
1e-2 lies a decade below h ≈ 0.1, where the regular part of the gap distribution takes over.
At the bottom of the window the deviation is a finite-size depletion of the smallest values,
which the cut-off model cannot absorb: on depleted synthetic gaps the test picks the cut-off
and that doubles the bias (docs/notes/fit-models.md).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from ..result import JammingResult
from ._inputs import as_results
from .fits import FIT_MODELS, MIN_RELIABLE_POINTS, PowerLawFit, fit_cumulative_power_law
from .forces import DEFAULT_RULE, split_forces
from .gaps import DEFAULT_MAX_GAP, pooled_gaps
from .sample import PooledSample

__all__ = ["REFERENCE_EXPONENTS", "SYMBOLS", "UPPER", "MODEL", "SCAN_STEPS", "resolve_models",
           "Exponent", "exponent_from_sample", "critical_exponents", "window_scan"]

#: Reference values (Charbonneau et al. 2014; θ_ℓ = 1 − 2γ from Lerner, Düring & Wyart 2013).
REFERENCE_EXPONENTS: dict[str, float] = {"gamma": 0.41269, "theta_e": 0.42311,
                                         "theta_l": 0.17, "theta": 0.17}
#: How each exponent is written in reports and warnings.
SYMBOLS: dict[str, str] = {"gamma": "γ", "theta_e": "θ_e", "theta_l": "θ_ℓ", "theta": "θ"}
#: Default upper end of each fit window (gap h, or force in units of the mean force).
UPPER: dict[str, float] = {"gamma": 1e-2, "theta_e": 0.3, "theta_l": 0.3, "theta": 0.3}
#: Default fit model of each exponent (`calippso.analysis.fits`; see the module notes).
MODEL: dict[str, str] = {"gamma": "power_law", "theta_e": "auto", "theta_l": "auto",
                         "theta": "auto"}
#: Window tops tried by `window_scan`: UPPER[name] × 10^(k/4) for these k.
SCAN_STEPS: tuple[int, ...] = (-8, -7, -6, -5, -4, -3, -2, -1, 0, 1, 2, 3, 4)
#: exponent = offset + sign × slope of the cumulative.
_FROM_SLOPE: dict[str, tuple[float, float]] = {"gamma": (1.0, -1.0), "theta_e": (-1.0, 1.0),
                                               "theta_l": (-1.0, 1.0), "theta": (-1.0, 1.0)}


@dataclass(frozen=True)
class Exponent:
    """A measured exponent with its bootstrap interval and the fit behind it.

    Attributes
    ----------
    name : str
        "gamma", "theta_e", "theta_l" or "theta".
    value : float
    interval : tuple of float
        Bootstrap percentile interval (low, high).
    reference : float
        The value from the literature (`REFERENCE_EXPONENTS`).
    fit : PowerLawFit
        The fit of the cumulative (slope, window, points).
    """

    name: str
    value: float
    interval: tuple[float, float]
    reference: float
    fit: PowerLawFit

    @property
    def deviation(self) -> float:
        """value − reference."""
        return self.value - self.reference

    @property
    def warning(self) -> str | None:
        """Why the value is not a measurement: its fit window holds fewer than
        `MIN_RELIABLE_POINTS` values (None when it holds enough)."""
        points = self.fit.n_points
        if points >= MIN_RELIABLE_POINTS:
            return None
        return (f"{SYMBOLS[self.name]} = {self.value:.3g} rests on only {points} values in its "
                f"fit window (with fewer than {MIN_RELIABLE_POINTS} a fitted exponent can be "
                f"off by 0.1 or more): pool more packings")

    def to_dict(self) -> dict:
        """Plain numbers, for JSON (and the `warning`, or None)."""
        return {"value": self.value, "interval": list(self.interval),
                "reference": self.reference, "window": [self.fit.lower, self.fit.upper],
                "points_in_window": self.fit.n_points, "confidence": self.fit.confidence,
                "bootstrap_resamples": self.fit.n_bootstrap,
                "bootstrap_over": self.fit.resampling, "estimator": self.fit.method,
                "model": self.fit.model, "cutoff": self.fit.cutoff,
                "power_law_p_value": self.fit.p_value, "warning": self.warning}


def resolve_models(model: str | dict[str, str] | None) -> dict[str, str]:
    """The fit model of every exponent: `MODEL`, one model for all, or `MODEL` updated.

    Parameters
    ----------
    model : None, str or dict
        None: the defaults `MODEL`; a model name ("auto", "power_law", "cutoff"): that model
        for every exponent; a dict {exponent name: model}: those entries replace the
        defaults.
    """
    if model is None:
        return dict(MODEL)
    chosen = {name: model for name in MODEL} if isinstance(model, str) else {**MODEL, **model}
    for name, value in chosen.items():
        if name not in MODEL:
            raise ValueError(f"unknown exponent {name!r} in model (one of {tuple(MODEL)})")
        if value not in FIT_MODELS:
            raise ValueError(f"model must be one of {FIT_MODELS}, got {value!r}")
    return chosen


def exponent_from_sample(name: str, sample: PooledSample, *, upper: float | None = None,
                         model: str | None = None, **fit_options) -> Exponent:
    """Fit the cumulative of `sample` and convert its slope into the exponent `name`.

    Parameters
    ----------
    name : {"gamma", "theta_e", "theta_l", "theta"}
    sample : PooledSample
        Gaps (for "gamma") or forces normalised by the mean.
    upper : float, optional
        Upper end of the fit window (default `UPPER[name]`).
    model : {"auto", "power_law", "cutoff"}, optional
        Fit model (default `MODEL[name]`; with method "lsq", "auto" fits the pure power law).
    **fit_options
        Passed to `fit_cumulative_power_law` (min_count, method, n_bootstrap, confidence,
        seed).
    """
    if name not in _FROM_SLOPE:
        raise ValueError(f"name must be one of {tuple(_FROM_SLOPE)}, got {name!r}")
    fit = fit_cumulative_power_law(sample, UPPER[name] if upper is None else upper,
                                   model=MODEL[name] if model is None else model, **fit_options)
    offset, sign = _FROM_SLOPE[name]
    ends = sorted(offset + sign * s for s in fit.interval)
    return Exponent(name, offset + sign * fit.slope, (ends[0], ends[1]),
                    REFERENCE_EXPONENTS[name], fit)


def critical_exponents(results: JammingResult | Iterable[JammingResult], *,
                       max_gap: float = DEFAULT_MAX_GAP, rule: str = DEFAULT_RULE,
                       upper: dict[str, float] | None = None,
                       model: str | dict[str, str] | None = None,
                       **fit_options) -> dict[str, Exponent]:
    """γ, θ_e, θ_ℓ and θ pooled over `results`.

    Parameters
    ----------
    results : JammingResult or iterable of JammingResult
    max_gap : float
        Largest gap collected (must exceed the gap window's upper end).
    rule : {"bucklers", "weakest", "response"}
        Localisation rule (`calippso.analysis.forces.localized_contacts`).
    upper : dict, optional
        Upper ends of the fit windows, by exponent name (defaults: `UPPER`).
    model : None, str or dict
        Fit models (`resolve_models`; defaults: `MODEL`).
    **fit_options
        Passed to `fit_cumulative_power_law`.

    Returns
    -------
    dict
        {"gamma": Exponent, "theta_e": Exponent, "theta_l": Exponent, "theta": Exponent}

    Raises
    ------
    ValueError
        Too few small gaps or forces for a fit (pool more packings).
    """
    results = as_results(results)
    uppers = {**UPPER, **(upper or {})}
    models = resolve_models(model)
    forces = split_forces(results, rule)
    samples = {"gamma": pooled_gaps(results, max_gap), "theta_e": forces["extended"],
               "theta_l": forces["localized"], "theta": forces["all"]}
    return {name: exponent_from_sample(name, sample, upper=uppers[name], model=models[name],
                                       **fit_options)
            for name, sample in samples.items()}


def window_scan(name: str, sample: PooledSample, *, upper: float | None = None,
                largest: float | None = None, min_count: int = 10) -> list[dict]:
    """The exponent fitted with the window top moved over 3 decades around `upper`.

    The check of the window rule: where a pure power law holds, its exponent does not drift
    as the top of the window moves (within the statistical error of the smaller windows); a
    steady drift is the first-order correction that the cut-off model absorbs.

    Parameters
    ----------
    name : {"gamma", "theta_e", "theta_l", "theta"}
    sample : PooledSample
    upper : float, optional
        The window top of the measurement (default `UPPER[name]`); tops
        upper × 10^(k/4), k in `SCAN_STEPS`, are tried.
    largest : float, optional
        No top above this (e.g. the largest gap collected).
    min_count : int
        As in `fit_cumulative_power_law`.

    Returns
    -------
    list of dict
        {"upper", "points", "power_law", "cutoff", "p_value"} for every top whose window
        holds enough points, in increasing order of the top (maximum likelihood, no
        bootstrap): the exponent with the pure power law, the exponent with the cut-off
        model, and the likelihood-ratio p-value of the pure power law.
    """
    if name not in _FROM_SLOPE:
        raise ValueError(f"name must be one of {tuple(_FROM_SLOPE)}, got {name!r}")
    top = UPPER[name] if upper is None else upper
    offset, sign = _FROM_SLOPE[name]
    rows = []
    for k in SCAN_STEPS:
        candidate = top * 10.0 ** (k / 4)
        if largest is not None and candidate > largest * (1 + 1e-12):
            continue
        try:
            fits = {model: fit_cumulative_power_law(sample, candidate, min_count=min_count,
                                                    model=model, n_bootstrap=0)
                    for model in ("power_law", "cutoff")}
        except ValueError:
            continue
        rows.append({"upper": float(candidate), "points": fits["power_law"].n_points,
                     **{model: offset + sign * fit.slope for model, fit in fits.items()},
                     "p_value": fits["cutoff"].p_value})
    return rows
