"""Power-law fits of the small-argument tail of an empirical cumulative, with bootstrap intervals.

Fit window rule
---------------
The cumulative C(x_k) = k / normalization of the sorted sample is fitted as C(x) ≈ A x^α over
the window of sample points x_k with

* x_k ≥ a = x_(min_count), the `min_count`-th smallest value (default 10): below it the
  cumulative is a handful of counts, dominated by Poisson noise and by the finite-size cut-off
  of the smallest gaps or forces;
* x_k ≤ b = `upper`, a cap on the argument fixed per quantity (`calippso.analysis.exponents`).

Estimator
---------
``method="mle"`` (default): maximum likelihood of α for the values inside the window, given that
they lie in it: if C ∝ x^α on [a, b], each value has the conditional distribution function
(x^α − a^α) / (b^α − a^α) (density ∝ x^(α−1)). This is the estimator recommended for power
laws by Clauset, Shalizi & Newman (SIAM Review 51, 661, 2009) with a window bounded on both
sides; it does not depend on how many values lie below the window (only the shape inside it
counts), and on synthetic samples it is unbiased and has a ~25 % smaller spread than the least
squares below. The amplitude A puts the fitted line through the empirical cumulative at the
top of the window.

``method="lsq"``: straight-line least squares of log C against log x over the window points
(the estimator used before; kept for comparison).

Bootstrap
---------
The interval is the percentile interval of α over `n_bootstrap` resamples, each refitted with
the same rule. When the sample pools at least `MIN_GROUPS_FOR_PACKING_BOOTSTRAP` packings, whole
packings are resampled (so that correlations within a packing are respected); otherwise
individual values are resampled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from .sample import PooledSample

__all__ = ["FIT_METHODS", "MIN_GROUPS_FOR_PACKING_BOOTSTRAP", "PowerLawFit",
           "fit_cumulative_power_law"]

#: Pooled packings from which the bootstrap resamples packings instead of values.
MIN_GROUPS_FOR_PACKING_BOOTSTRAP = 8
#: Fewest sample points accepted in a fit window.
MIN_POINTS = 10


@dataclass(frozen=True)
class PowerLawFit:
    """C(x) ≈ amplitude × x^slope over lower ≤ x ≤ upper.

    Attributes
    ----------
    slope : float
        Fitted exponent α of the cumulative.
    interval : tuple of float
        Bootstrap percentile interval of α at the given confidence.
    amplitude : float
        A, in the units of the cumulative.
    lower, upper : float
        The fit window, in the units of the sample.
    n_points : int
        Sample points inside the window.
    n_bootstrap : int
        Resamples behind the interval.
    confidence : float
        Confidence level of the interval.
    resampling : str
        "packings" or "values".
    method : str
        "mle" or "lsq" (see the module notes).
    """

    slope: float
    interval: tuple[float, float]
    amplitude: float
    lower: float
    upper: float
    n_points: int
    n_bootstrap: int
    confidence: float
    resampling: str
    method: str = "mle"

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The fitted cumulative at `x`."""
        return self.amplitude * np.asarray(x, dtype=np.float64) ** self.slope


#: Estimators accepted by `fit_cumulative_power_law`.
FIT_METHODS = ("mle", "lsq")


def _window_mle(x: np.ndarray, a: float, b: float) -> float:
    """Maximum-likelihood α for values `x` in [a, b] with density ∝ x^(α−1) on [a, b]."""
    mean_log = float(np.mean(np.log(x)))
    la, lb = np.log(a), np.log(b)
    span = lb - la
    if not span > 0:
        raise ValueError("the fit window is empty (its ends coincide)")

    def score(alpha: float) -> float:
        # mean log x minus its expectation under the truncated power law
        t = alpha * span
        if abs(t) < 1e-8:
            expected = 0.5 * (la + lb)
        elif t < -700.0:                      # all the weight at the lower end
            expected = la - 1.0 / alpha
        else:                                 # la + span / (1 − e^(−t)) − 1/α
            expected = la + span / -math.expm1(-t) - 1.0 / alpha
        return mean_log - expected

    # the expectation grows monotonically with α from la (α → −∞) to lb (α → +∞)
    lo, hi = -1.0, 1.0
    while score(lo) < 0:
        lo *= 2.0
        if lo < -1e4:
            return float(lo)
    while score(hi) > 0:
        hi *= 2.0
        if hi > 1e4:
            return float(hi)
    return float(brentq(score, lo, hi, xtol=1e-12))


def _fit(values: np.ndarray, normalization: float, upper: float, min_count: int,
         method: str) -> tuple[float, float, float, int]:
    """Slope, log-amplitude, lower end and point count of one fit (values sorted)."""
    ranks = np.arange(1, values.size + 1)
    inside = (ranks >= min_count) & (values <= upper) & (values > 0)
    n_points = int(np.count_nonzero(inside))
    if n_points < MIN_POINTS:
        raise ValueError(
            f"only {n_points} sample points between the {min_count}-th smallest value and "
            f"upper = {upper:g} (at least {MIN_POINTS} needed): pool more packings or raise "
            f"the upper end of the window")
    x = values[inside]
    c = ranks[inside] / normalization
    if method == "lsq":
        slope, intercept = np.polyfit(np.log(x), np.log(c), 1)
    else:
        slope = _window_mle(x, float(x[0]), float(upper))
        intercept = np.log(c[-1]) - slope * np.log(x[-1])
    return float(slope), float(intercept), float(x[0]), n_points


def fit_cumulative_power_law(sample: PooledSample | np.ndarray, upper: float, *,
                             min_count: int = 10, method: str = "mle",
                             n_bootstrap: int = 1000, confidence: float = 0.95,
                             seed: int = 0) -> PowerLawFit:
    """Fit C(x) ≈ A x^α to the small-x end of the empirical cumulative of `sample`.

    Parameters
    ----------
    sample : PooledSample or array_like, shape (K,)
        Positive values (an array is one group normalised by its length).
    upper : float
        Upper end of the fit window (units of the sample).
    min_count : int
        The window starts at the `min_count`-th smallest value.
    method : {"mle", "lsq"}
        Maximum likelihood inside the window (default) or least squares of log C on log x
        (see the module notes).
    n_bootstrap : int
        Bootstrap resamples (0: no interval, reported as (nan, nan)).
    confidence : float
        Level of the percentile interval, in (0, 1).
    seed : int
        Seed of the resampling.

    Returns
    -------
    PowerLawFit

    Raises
    ------
    ValueError
        Fewer than `MIN_POINTS` values in the window, or bad parameters.
    """
    if not isinstance(sample, PooledSample):
        sample = PooledSample.from_values(sample)
    if not upper > 0:
        raise ValueError(f"upper must be positive, got {upper!r}")
    if min_count < 1:
        raise ValueError(f"min_count must be at least 1, got {min_count!r}")
    if method not in FIT_METHODS:
        raise ValueError(f"method must be one of {FIT_METHODS}, got {method!r}")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    slope, intercept, lower, n_points = _fit(sample.values, sample.normalization, upper,
                                             min_count, method)
    by_packing = sample.n_groups >= MIN_GROUPS_FOR_PACKING_BOOTSTRAP
    rng = np.random.default_rng(seed)
    slopes = np.full(n_bootstrap, np.nan)
    if by_packing:
        members = [sample.values[sample.groups == g] for g in range(sample.n_groups)]
    for b in range(n_bootstrap):
        if by_packing:
            chosen = rng.integers(0, sample.n_groups, sample.n_groups)
            values = np.sort(np.concatenate([members[g] for g in chosen]))
            normalization = float(sample.group_normalizations[chosen].sum())
        else:
            values = np.sort(rng.choice(sample.values, size=len(sample), replace=True))
            normalization = sample.normalization
        try:
            slopes[b] = _fit(values, normalization, upper, min_count, method)[0]
        except ValueError:  # a resample with too few small values: left out of the interval
            continue
    tail = 50.0 * (1.0 - confidence)
    finite = slopes[np.isfinite(slopes)]
    interval = ((float(np.percentile(finite, tail)), float(np.percentile(finite, 100 - tail)))
                if finite.size else (float("nan"), float("nan")))
    return PowerLawFit(slope=slope, interval=interval, amplitude=float(np.exp(intercept)),
                       lower=lower, upper=float(upper), n_points=n_points,
                       n_bootstrap=int(finite.size), confidence=float(confidence),
                       resampling="packings" if by_packing else "values", method=method)
