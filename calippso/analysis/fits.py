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
squares below. The amplitude A puts the fitted curve through the empirical cumulative at the
top of the window.

``method="lsq"``: straight-line least squares of log C against log x over the window points
(the estimator used before; kept for comparison; pure power law only).

Model: pure power law, or power law with an exponential cut-off
----------------------------------------------------------------
A density that is a power law only asymptotically, p(x) ∝ x^(α−1) (1 − λ x + …), gives a pure
power-law fit whose slope drifts with the window top (docs/notes/fit-models.md).
``model="cutoff"`` fits the density
x^(α−1) e^(−λ x) on [a, b] instead, with α and λ both free (λ of either sign): the power law
with exponential cut-off of Clauset, Shalizi & Newman (their section 5), which absorbs the
first-order correction, so that α is the exponent of the x → 0 limit. Its likelihood is that
of a two-parameter exponential family (sufficient statistics mean log x and mean x), concave,
maximised by Newton's method with trust region (`scipy.optimize.minimize`, "trust-exact");
the normalisation integral is a 64-point Gauss–Legendre rule in log x. The fitted cumulative is
C(x) = A x^α ₁F₁(α; α + 1; −λ x), which tends to A x^α at small x.

``model="auto"`` (default) chooses between them by the likelihood-ratio test of the nested
pair (Clauset, Shalizi & Newman, section 5; λ = 0 is inside the parameter range, so twice the
log-likelihood gain is χ² with one degree of freedom under the pure power law): the cut-off
model is used when the pure power law is rejected at `LR_SIGNIFICANCE` (5 %), the pure power
law otherwise. The p-value is part of the result either way.

Bootstrap
---------
The interval is the percentile interval of α over `n_bootstrap` resamples, each refitted with
the same window rule and the model chosen on the full sample. When the sample pools at least
`MIN_GROUPS_FOR_PACKING_BOOTSTRAP` packings, whole packings are resampled (so that
correlations within a packing are respected); otherwise individual values are resampled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, minimize
from scipy.special import hyp1f1
from scipy.stats import chi2

from .resampling import window_sums
from .sample import PooledSample

__all__ = ["FIT_METHODS", "FIT_MODELS", "LR_SIGNIFICANCE", "MIN_GROUPS_FOR_PACKING_BOOTSTRAP",
           "MIN_POINTS", "MIN_RELIABLE_POINTS", "PowerLawFit", "fit_cumulative_power_law",
           "window_mle"]

#: Pooled packings from which the bootstrap resamples packings instead of values.
MIN_GROUPS_FOR_PACKING_BOOTSTRAP = 8
#: Fewest sample points accepted in a fit window.
MIN_POINTS = 10
#: Fewest points in a fit window for an exponent to be read as a measurement; with fewer
#: the fit is still made but flagged (`calippso.analysis.exponents.Exponent.warning`).
#: Below 400 points the spread of a fitted exponent between samples exceeds half the gap
#: between the θ_e and θ_ℓ references (docs/analysis.md, Reports).
MIN_RELIABLE_POINTS = 400
#: Estimators accepted by `fit_cumulative_power_law`.
FIT_METHODS = ("mle", "lsq")
#: Models accepted by `fit_cumulative_power_law` (see the module notes).
FIT_MODELS = ("auto", "power_law", "cutoff")
#: Level at which model "auto" rejects the pure power law for the cut-off model.
LR_SIGNIFICANCE = 0.05
#: Gradient of the mean log-likelihood at which the cut-off fit stops.
GRADIENT_TOLERANCE = 1e-9
#: Gauss–Legendre rule for the normalisation of the cut-off model (in log x).
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(64)


@dataclass(frozen=True)
class PowerLawFit:
    """C(x) ≈ amplitude × x^slope × ₁F₁(slope; slope + 1; −cutoff × x) over lower ≤ x ≤ upper.

    Attributes
    ----------
    slope : float
        Fitted exponent α of the cumulative (of its x → 0 limit with the cut-off model).
    interval : tuple of float
        Bootstrap percentile interval of α at the given confidence.
    amplitude : float
        A, in the units of the cumulative times x^(−α).
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
    model : str
        "power_law" or "cutoff": the model fitted (with model "auto", the one the
        likelihood-ratio test chose).
    cutoff : float
        λ of the cut-off model, density ∝ x^(α−1) e^(−λ x), in units of 1/x (0 for the pure
        power law).
    p_value : float
        Likelihood-ratio p-value of the pure power law against the cut-off model in the window
        (small: the pure power law is rejected); nan with method "lsq".
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
    model: str = "power_law"
    cutoff: float = 0.0
    p_value: float = float("nan")

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The fitted cumulative at `x`."""
        return self.amplitude * _shape(np.asarray(x, dtype=np.float64), self.slope, self.cutoff)


def _shape(x: np.ndarray, alpha: float, cutoff: float) -> np.ndarray:
    """x^α ₁F₁(α; α + 1; −λ x): α ∫_0^x t^(α−1) e^(−λ t) dt, the cumulative of the model."""
    with np.errstate(over="ignore", under="ignore"):  # a far-off slope of a tiny window
        power = x ** alpha
    return power if cutoff == 0.0 else power * hyp1f1(alpha, alpha + 1.0, -cutoff * x)


def _power_law_loglik(mean_log: float, alpha: float, la: float, span: float) -> float:
    """Mean log-likelihood of density α x^(α−1) / (b^α − a^α) on [a, b], span = ln(b/a)."""
    t = alpha * span
    if abs(t) < 1e-8:
        # density 1 / (x ln(b/a)), with its first order in α
        return -math.log(span) - mean_log + alpha * (mean_log - la - 0.5 * span)
    # b^α − a^α = a^α expm1(α span)
    return (math.log(abs(alpha)) - alpha * la - math.log(abs(math.expm1(t)))
            + (alpha - 1.0) * mean_log)


def window_mle(x: np.ndarray, a: float, b: float) -> float:
    """Maximum-likelihood exponent α of a pure power law on a fixed window [a, b].

    Parameters
    ----------
    x : array_like, shape (K,)
        The sample values inside the window (all in [a, b], positive).
    a, b : float
        Lower and upper ends of the window, 0 < a < b (units of `x`).

    Returns
    -------
    float
        α of the density ∝ x^(α−1) on [a, b] (cumulative C ∝ x^α) that maximises the
        likelihood of `x`; ±1e4 or beyond when the values pile up at one end.

    Raises
    ------
    ValueError
        The window is empty (a = b).
    """
    return _power_law_mle(float(np.mean(np.log(np.asarray(x, dtype=float)))), a, b)


def _power_law_mle(mean_log: float, a: float, b: float) -> float:
    """`window_mle` from the sufficient statistic: the mean of log x over the window."""
    la, lb = math.log(a), math.log(b)
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




def _cutoff_mle(mean_log: float, mean_x: float, a: float, b: float,
                start: float) -> tuple[float, float, float]:
    """Maximum-likelihood (α, λ) for density ∝ x^(α−1) e^(−λ x) on [a, b].

    The model is an exponential family: the likelihood depends on the values in the window
    only through `mean_log` (mean of log x) and `mean_x` (mean of x). Returns α, λ (units
    1/x) and the mean log-likelihood at the maximum. The fit is done in t = x / b (μ = λ b)
    from α = `start`, μ = 0.
    """
    la, lb = math.log(a), math.log(b)
    u = 0.5 * (lb - la) * _NODES + 0.5 * (lb + la)        # quadrature nodes in log x
    log_w = np.log(0.5 * (lb - la) * _WEIGHTS)
    t_nodes = np.exp(u - lb)
    mean_t = mean_x / b

    cache: dict[tuple[float, float], tuple[float, np.ndarray, np.ndarray]] = {}

    def parts(p: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Negative mean log-likelihood, its gradient and Hessian (computed once per point)."""
        key = (float(p[0]), float(p[1]))
        if key not in cache:
            cache.clear()
            cache[key] = _cutoff_parts(*key)
        return cache[key]

    def _cutoff_parts(alpha: float, mu: float) -> tuple[float, np.ndarray, np.ndarray]:
        # the density in log x is e^(α u − μ t); normalise on the nodes
        e = log_w + alpha * u - mu * t_nodes
        top = float(e.max())
        q = np.exp(e - top)
        z = float(q.sum())
        prob = q / z
        du, dt = u - prob @ u, t_nodes - prob @ t_nodes
        value = -((alpha - 1.0) * mean_log - mu * mean_t - (top + math.log(z)))
        gradient = np.array([prob @ u - mean_log, mean_t - prob @ t_nodes])
        cross = float(prob @ (du * dt))
        hessian = np.array([[prob @ du ** 2, -cross], [-cross, prob @ dt ** 2]])
        return value, gradient, hessian

    solution = minimize(lambda p: parts(p)[0], x0=np.array([start, 0.0]),
                        jac=lambda p: parts(p)[1], hess=lambda p: parts(p)[2],
                        method="trust-exact", options={"gtol": GRADIENT_TOLERANCE})
    # near the optimum round-off can stop the trust region short of gtol: a small gradient
    # is accepted whatever the message
    settled = np.all(np.isfinite(solution.x)) and np.all(
        np.abs(parts(solution.x)[1]) < 100 * GRADIENT_TOLERANCE)
    if not (solution.success or settled):
        raise ValueError(f"the cut-off fit did not converge: {solution.message}")
    alpha, mu = (float(v) for v in solution.x)
    return alpha, mu / b, -float(solution.fun)


def _mle(n_points: int, mean_log: float, mean_x: float, a: float, b: float,
         model: str) -> tuple[float, float, float, str]:
    """Slope, cut-off λ, p-value of the pure law and model of the likelihood fit of a
    window [a, b] holding `n_points` values with these means; "auto" is resolved here."""
    slope, cutoff, p_value = _power_law_mle(mean_log, a, b), 0.0, float("nan")
    if model != "power_law":
        pure = _power_law_loglik(mean_log, slope, math.log(a), math.log(b / a))
        alpha, lam, loglik = _cutoff_mle(mean_log, mean_x, a, b, start=slope)
        p_value = float(chi2.sf(max(0.0, 2.0 * n_points * (loglik - pure)), df=1))
        if model == "auto":
            model = "cutoff" if p_value < LR_SIGNIFICANCE else "power_law"
        if model == "cutoff":
            slope, cutoff = alpha, lam
    return slope, cutoff, p_value, model


def _fit(values: np.ndarray, normalization: float, upper: float, min_count: int,
         method: str, model: str, lower: float = 0.0) -> PowerLawFit:
    """One fit of the sorted `values` (no interval); model "auto" is resolved here."""
    ranks = np.arange(1, values.size + 1)
    ranked = (ranks >= min_count) & (values > 0)
    inside = ranked & (values <= upper) & (values >= lower)
    n_points = int(np.count_nonzero(inside))
    if n_points < MIN_POINTS:
        floor = f"lower = {lower:g} and " if lower > 0 else ""
        raise ValueError(
            f"only {n_points} sample points between {floor}the {min_count}-th smallest value "
            f"and upper = {upper:g} (at least {MIN_POINTS} needed): pool more packings or "
            f"widen the window")
    x = values[inside]
    c = ranks[inside] / normalization
    a, b = max(float(lower), float(values[ranked][0])), float(upper)
    cutoff, p_value = 0.0, float("nan")
    if method == "lsq":
        slope = float(np.polyfit(np.log(x), np.log(c), 1)[0])
        model = "power_law"
    else:
        slope, cutoff, p_value, model = _mle(n_points, float(np.mean(np.log(x))),
                                             float(np.mean(x)), a, b, model)
    amplitude = float(c[-1] / _shape(np.array([x[-1]]), slope, cutoff)[0])
    return PowerLawFit(slope=float(slope), interval=(float("nan"), float("nan")),
                       amplitude=amplitude, lower=a, upper=b, n_points=n_points, n_bootstrap=0,
                       confidence=float("nan"), resampling="", method=method, model=model,
                       cutoff=float(cutoff), p_value=p_value)


def fit_cumulative_power_law(sample: PooledSample | np.ndarray, upper: float, *,
                             min_count: int = 10, method: str = "mle", model: str = "auto",
                             n_bootstrap: int = 1000, confidence: float = 0.95,
                             seed: int = 0, lower: float = 0.0) -> PowerLawFit:
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
    model : {"auto", "power_law", "cutoff"}
        Density x^(α−1), or x^(α−1) e^(−λ x), in the window; "auto" (default) takes the
        cut-off model when the likelihood-ratio test rejects the pure power law at
        `LR_SIGNIFICANCE`. Method "lsq" fits the pure power law only.
    n_bootstrap : int
        Bootstrap resamples (0: no interval, reported as (nan, nan)).
    confidence : float
        Level of the percentile interval, in (0, 1).
    seed : int
        Seed of the resampling.
    lower : float
        A floor of the window (units of the sample): it starts at the larger of `lower` and
        the `min_count`-th smallest value (default 0: the rank rule alone), e.g. above a
        finite-size cut-off of the smallest values.

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
    if not 0 <= lower < upper:
        raise ValueError(f"lower must lie in [0, upper), got {lower!r}")
    if min_count < 1:
        raise ValueError(f"min_count must be at least 1, got {min_count!r}")
    if method not in FIT_METHODS:
        raise ValueError(f"method must be one of {FIT_METHODS}, got {method!r}")
    if model not in FIT_MODELS:
        raise ValueError(f"model must be one of {FIT_MODELS}, got {model!r}")
    if method == "lsq" and model == "cutoff":
        raise ValueError('model "cutoff" needs method "mle" (least squares fits a pure power '
                         'law)')
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    fit = _fit(sample.values, sample.normalization, upper, min_count, method, model, lower)
    by_packing = sample.n_groups >= MIN_GROUPS_FOR_PACKING_BOOTSTRAP
    rng = np.random.default_rng(seed)
    if method == "mle":
        slopes = _resampled_mle(sample, upper, min_count, n_bootstrap, rng, by_packing,
                                fit.model, lower)
    else:
        slopes = _resampled_lsq(sample, upper, min_count, n_bootstrap, rng, by_packing, lower)
    tail = 50.0 * (1.0 - confidence)
    finite = slopes[np.isfinite(slopes)]
    interval = ((float(np.percentile(finite, tail)), float(np.percentile(finite, 100 - tail)))
                if finite.size else (float("nan"), float("nan")))
    return PowerLawFit(slope=fit.slope, interval=interval, amplitude=fit.amplitude,
                       lower=fit.lower, upper=fit.upper, n_points=fit.n_points,
                       n_bootstrap=int(finite.size), confidence=float(confidence),
                       resampling="packings" if by_packing else "values", method=method,
                       model=fit.model, cutoff=fit.cutoff, p_value=fit.p_value)


def _resampled_mle(sample: PooledSample, upper: float, min_count: int, n_bootstrap: int,
                   rng: np.random.Generator, by_packing: bool, model: str,
                   lower: float) -> np.ndarray:
    """The likelihood slope of every bootstrap resample, from its window sums
    (`calippso.analysis.resampling`); nan where the window holds too few values or the
    cut-off fit does not converge."""
    slopes = np.full(n_bootstrap, np.nan)
    for k, sums in enumerate(window_sums(sample, upper, min_count, n_bootstrap, rng,
                                         by_packing, lower)):
        if sums.n_points < MIN_POINTS or not sums.lower < upper:
            continue
        try:
            slopes[k] = _mle(sums.n_points, sums.mean_log, sums.mean_x, sums.lower, upper,
                             model)[0]
        except ValueError:  # no convergence: left out of the interval
            continue
    return slopes


def _resampled_lsq(sample: PooledSample, upper: float, min_count: int, n_bootstrap: int,
                   rng: np.random.Generator, by_packing: bool, lower: float) -> np.ndarray:
    """The least-squares slope of every bootstrap resample (each one sorted and refitted)."""
    slopes = np.full(n_bootstrap, np.nan)
    if by_packing:
        members = [sample.values[sample.groups == g] for g in range(sample.n_groups)]
    for k in range(n_bootstrap):
        if by_packing:
            chosen = rng.integers(0, sample.n_groups, sample.n_groups)
            values = np.sort(np.concatenate([members[g] for g in chosen]))
            normalization = float(sample.group_normalizations[chosen].sum())
        else:
            values = np.sort(sample.values[rng.integers(0, len(sample), len(sample))])
            normalization = sample.normalization
        try:
            slopes[k] = _fit(values, normalization, upper, min_count, "lsq", "power_law",
                             lower).slope
        except ValueError:  # too few small values: left out of the interval
            continue
    return slopes
