"""Extrapolation of a size-dependent measurement x(N), with its interval, to N → ∞.

Correction forms (`FORMS`), fitted by weighted least squares (weights 1/σ_i², σ_i from the
interval of each size, `sigma_of_interval`):

=============  =========================  ==========================================
form           x(N)                       parameters
=============  =========================  ==========================================
"constant"     x_∞                        1 (no trend with N)
"inverse_n"    x_∞ + a / N                2 (the correction of a finite number of
                                          particles)
"power"        x_∞ + a N^(−ω)             2 with ω given, 3 with ω fitted in
                                          `OMEGA_RANGE`
=============  =========================  ==========================================

Choice of the form (``form="auto"``): with four sizes or more, the power law with ω fitted;
with two or three, 1/N (ω = 1 assumed, stated in the reason). On synthetic trends
x_∞ + a N^(−ω) with ω from 0.3 to 1 and on constants (four or six sizes, σ = 0.005), the
fitted ω gives a 95 % interval that covers x_∞ in 96–100 % of the samples, where choosing
the form by the lowest AICc covers it in 0–39 % once ω < 1: four to six sizes cannot tell a
slow correction from a constant or 1/N, and the simpler form then extrapolates short
(docs/notes/finite-size.md, `bench/extrapolation_coverage.py`). The price is the width: the
interval of the fitted ω is 5–10 times wider than that of a form assumed. A fitted ω at the
lower end of `OMEGA_RANGE` means that the sizes resolve no trend: the reason then says so and
gives the constant form's fit.
Every form that the sizes allow is fitted and kept beside the choice with its χ², p-value
and small-sample Akaike criterion AICc = χ² + 2k + 2k(k + 1)/(S − k − 1) (S sizes, k
parameters; defined for S > k + 1), so that a form known in advance can be asked for.

Interval: parametric bootstrap. The values are redrawn from normal laws with their σ_i,
inflated by √(χ²/dof) when the chosen form fits worse than the intervals say (the Birge
ratio, never below 1); each draw is refitted with the chosen form (ω refitted when it is
fitted) and the percentile interval of x_∞ over the draws is reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.stats import chi2, norm

__all__ = ["FORMS", "OMEGA_RANGE", "OMEGA_AT_BOUND", "Correction", "Extrapolation",
           "extrapolate", "sigma_of_interval"]

#: Correction forms accepted by `extrapolate` (besides "auto").
FORMS = ("constant", "inverse_n", "power")
#: Bounds of a fitted correction exponent ω (below 0.1, N^(−ω) cannot be told from a
#: constant over the decades of N that packings span, and x_∞ runs away).
OMEGA_RANGE = (0.1, 3.0)
#: A fitted ω within this fraction of the lower bound of `OMEGA_RANGE` sits at the bound:
#: the sizes resolve no trend, and the reason says so beside the constant form's fit.
OMEGA_AT_BOUND = 1e-3
#: Points of the ω grid on which a fitted ω is searched (log-spaced over `OMEGA_RANGE`).
OMEGA_GRID_POINTS = 241
#: Draws of the parametric bootstrap by default.
DEFAULT_DRAWS = 2000
#: Sizes from which ``form="auto"`` fits ω (one more than the parameters of that form).
_FITTED_OMEGA_SIZES = 4
#: Parameters of each form (the power law with ω fitted: 3).
_PARAMETERS = {"constant": 1, "inverse_n": 2, "power": 2}


def sigma_of_interval(interval: np.ndarray, confidence: float = 0.95) -> np.ndarray:
    """Standard errors from two-sided intervals, read as normal: (high − low) / (2 z).

    Parameters
    ----------
    interval : array_like, shape (S, 2)
        (low, high) per measurement.
    confidence : float
        The level of the intervals, in (0, 1).

    Returns
    -------
    ndarray, shape (S,)
    """
    interval = np.asarray(interval, dtype=np.float64).reshape(-1, 2)
    return (interval[:, 1] - interval[:, 0]) / (2.0 * norm.ppf(0.5 + confidence / 2.0))


@dataclass(frozen=True)
class Correction:
    """One form fitted to x(N): x(N) = value + amplitude × N^(−omega).

    Attributes
    ----------
    form : str
        "constant", "inverse_n" or "power".
    value : float
        x_∞.
    interval : tuple of float
        Percentile interval of x_∞ over the bootstrap draws (nan, nan before the draws).
    amplitude : float
        a (0 for the constant).
    omega : float
        ω (1 for "inverse_n", nan for the constant).
    omega_fitted : bool
        Whether ω was fitted (`OMEGA_RANGE`) or given.
    chi2 : float
        Σ (x_i − x(N_i))² / σ_i².
    dof : int
        Sizes less parameters.
    p_value : float
        P(χ²_dof ≥ chi2): small when the form does not describe the sizes within their
        intervals (nan when dof = 0).
    aicc : float
        The small-sample Akaike criterion (inf when not defined).
    """

    form: str
    value: float
    interval: tuple[float, float]
    amplitude: float
    omega: float
    omega_fitted: bool
    chi2: float
    dof: int
    p_value: float
    aicc: float

    @property
    def parameters(self) -> int:
        """Fitted parameters."""
        return _PARAMETERS[self.form] + int(self.omega_fitted)

    def __call__(self, n: np.ndarray) -> np.ndarray:
        """x(N) of the fitted form."""
        n = np.asarray(n, dtype=np.float64)
        if self.form == "constant":
            return np.full(n.shape, self.value)
        return self.value + self.amplitude * n ** (-self.omega)

    def to_dict(self) -> dict:
        """Plain numbers, for JSON."""
        return {"form": self.form, "value": self.value, "interval": list(self.interval),
                "amplitude": self.amplitude, "omega": self.omega,
                "omega_fitted": self.omega_fitted, "chi2": self.chi2, "dof": self.dof,
                "p_value": self.p_value, "aicc": self.aicc}


@dataclass(frozen=True)
class Extrapolation:
    """x(N) measured at several sizes and its limit N → ∞.

    Attributes
    ----------
    sizes : ndarray, shape (S,)
        N of each measurement, ascending.
    values : ndarray, shape (S,)
    sigmas : ndarray, shape (S,)
        Standard errors (`sigma_of_interval`).
    chosen : Correction
        The form kept, with the interval of x_∞.
    candidates : dict of str to Correction
        Every form fitted (no intervals except the chosen one's), by form.
    reason : str
        How the form was chosen, in words.
    """

    sizes: np.ndarray
    values: np.ndarray
    sigmas: np.ndarray
    chosen: Correction
    candidates: dict[str, Correction] = field(default_factory=dict)
    reason: str = ""

    @property
    def value(self) -> float:
        """x_∞ of the chosen form."""
        return self.chosen.value

    @property
    def interval(self) -> tuple[float, float]:
        """The interval of x_∞."""
        return self.chosen.interval

    def to_dict(self) -> dict:
        """Plain numbers, for JSON: value, interval, the chosen form and every candidate."""
        return {"value": self.value, "interval": list(self.interval), **{
            k: v for k, v in self.chosen.to_dict().items() if k not in ("value", "interval")},
            "reason": self.reason,
            "candidates": {form: c.to_dict() for form, c in self.candidates.items()}}


def _design(n: np.ndarray, omega: float | np.ndarray, form: str) -> np.ndarray:
    """Columns (1, N^(−ω)) (or (1) for the constant): shape (S, k), or (G, S, k) for a grid
    of ω."""
    if form == "constant":
        return np.ones((n.size, 1))
    omega = np.asarray(omega, dtype=np.float64)
    powers = n[None, :] ** (-omega.reshape(-1, 1))
    design = np.stack([np.ones_like(powers), powers], axis=-1)
    return design[0] if omega.ndim == 0 else design


def _weighted_fit(design: np.ndarray, values: np.ndarray,
                  weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least squares of `values` (shape (..., S) or (D, S)) on `design`
    (shape (..., S, k)): the parameters (..., D, k) and the χ² (..., D)."""
    root = np.sqrt(weights)
    a = design * root[:, None]
    b = np.atleast_2d(values) * root                                # (D, S)
    pinv = np.linalg.pinv(a)                                        # (..., k, S)
    params = np.einsum("...ks,ds->...dk", pinv, b)
    residual = b - np.einsum("...sk,...dk->...ds", a, params)
    return params, np.sum(residual ** 2, axis=-1)


def _fit_form(n: np.ndarray, values: np.ndarray, weights: np.ndarray, form: str,
              omega: float | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Best x_∞, a, ω and χ² of one form for every row of `values` (D, S): four arrays of
    shape (D,); ω fitted on the grid when `omega` is None for the form "power"."""
    if form == "constant":
        params, chi = _weighted_fit(_design(n, 0.0, form), values, weights)
        return params[:, 0], np.zeros(len(params)), np.full(len(params), np.nan), chi
    if form == "inverse_n" or omega is not None:
        given = 1.0 if form == "inverse_n" else float(omega)
        params, chi = _weighted_fit(_design(n, given, form), values, weights)
        return params[:, 0], params[:, 1], np.full(len(params), given), chi
    grid = np.geomspace(*OMEGA_RANGE, OMEGA_GRID_POINTS)
    params, chi = _weighted_fit(_design(n, grid, form), values, weights)   # (G, D, k), (G, D)
    best = np.argmin(chi, axis=0)
    rows = np.arange(values.shape[0])
    return params[best, rows, 0], params[best, rows, 1], grid[best], chi[best, rows]


def _refined_omega(n: np.ndarray, values: np.ndarray, weights: np.ndarray,
                   start: float) -> tuple[float, float, float, float]:
    """x_∞, a, ω, χ² of the power law with ω fitted, refined from the grid's best ω."""
    grid = np.geomspace(*OMEGA_RANGE, OMEGA_GRID_POINTS)
    k = int(np.argmin(np.abs(grid - start)))
    low, high = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]

    def chi_of(omega: float) -> float:
        return float(_weighted_fit(_design(n, omega, "power"), values, weights)[1][0])

    omega = float(minimize_scalar(chi_of, bounds=(low, high), method="bounded",
                                  options={"xatol": 1e-6}).x)
    if chi_of(start) < chi_of(omega):
        omega = float(start)
    params, chi = _weighted_fit(_design(n, omega, "power"), values, weights)
    return float(params[0, 0]), float(params[0, 1]), omega, float(chi[0])


def _candidate(n: np.ndarray, values: np.ndarray, sigmas: np.ndarray, form: str,
               omega: float | None) -> Correction:
    """One form fitted to the measurements (its interval is drawn later, if chosen)."""
    weights = 1.0 / sigmas ** 2
    x_inf, amp, om, chi = (float(v[0]) for v in _fit_form(n, values[None, :], weights, form,
                                                           omega))
    fitted = form == "power" and omega is None
    if fitted:
        x_inf, amp, om, chi = _refined_omega(n, values[None, :], weights, om)
    k = _PARAMETERS[form] + int(fitted)
    dof = n.size - k
    p_value = float(chi2.sf(chi, dof)) if dof > 0 else float("nan")
    aicc = chi + 2 * k + 2 * k * (k + 1) / (n.size - k - 1) if n.size > k + 1 else math.inf
    return Correction(form=form, value=x_inf, interval=(float("nan"), float("nan")),
                      amplitude=amp, omega=om, omega_fitted=fitted, chi2=chi, dof=dof,
                      p_value=p_value, aicc=float(aicc))


def _choose(n_sizes: int) -> tuple[str, str]:
    """The form kept by ``form="auto"`` and why (see the module notes)."""
    if n_sizes >= _FITTED_OMEGA_SIZES:
        return "power", f"{n_sizes} sizes: the correction's exponent ω is fitted"
    return "inverse_n", (f"{n_sizes} sizes: too few to fit ω (at least "
                         f"{_FITTED_OMEGA_SIZES} needed), 1/N assumed")


def extrapolate(sizes, values, intervals, *, form: str = "auto", omega: float | None = None,
                confidence: float = 0.95, n_draws: int = DEFAULT_DRAWS,
                seed: int = 0) -> Extrapolation:
    """Fit the correction forms to x(N) and extrapolate to N → ∞ (see the module notes).

    Parameters
    ----------
    sizes : array_like, shape (S,)
        N of each measurement (positive, distinct, S ≥ 2).
    values : array_like, shape (S,)
        The measurement at each size.
    intervals : array_like, shape (S, 2)
        Its two-sided interval at `confidence` (read as normal, `sigma_of_interval`).
    form : {"auto", "constant", "inverse_n", "power"}
        The correction form, or "auto" (see the module notes).
    omega : float, optional
        Fix ω of the form "power" (default: fitted in `OMEGA_RANGE`); with "auto" the
        power law with this ω is used.
    confidence : float
        Level of the intervals given and of the interval returned.
    n_draws : int
        Draws of the parametric bootstrap.
    seed : int

    Returns
    -------
    Extrapolation

    Raises
    ------
    ValueError
        Fewer than two sizes, repeated sizes, intervals of zero or undefined width, an
        unknown form, or a form with more parameters than sizes.
    """
    n = np.asarray(sizes, dtype=np.float64).ravel()
    x = np.asarray(values, dtype=np.float64).ravel()
    order = np.argsort(n)
    n, x = n[order], x[order]
    if n.size < 2 or x.shape != n.shape:
        raise ValueError(f"extrapolation needs values at two or more sizes, got {n.size}")
    if np.any(np.diff(n) == 0) or np.any(n <= 0):
        raise ValueError(f"sizes must be positive and distinct, got {n.tolist()}")
    if not 0 < confidence < 1:
        raise ValueError(f"confidence must lie in (0, 1), got {confidence!r}")
    sigmas = sigma_of_interval(intervals, confidence).ravel()[order]
    if sigmas.shape != n.shape or not np.all(np.isfinite(sigmas) & (sigmas > 0)):
        raise ValueError("every size needs an interval of positive, finite width")
    if form != "auto" and form not in FORMS:
        raise ValueError(f"form must be 'auto' or one of {FORMS}, got {form!r}")
    if omega is not None and not omega > 0:
        raise ValueError(f"omega must be positive, got {omega!r}")
    candidates = {f: _candidate(n, x, sigmas, f, omega) for f in FORMS
                  if n.size >= _PARAMETERS[f] + int(f == "power" and omega is None)}
    if form == "auto":
        chosen, reason = _choose(n.size) if omega is None else ("power", "ω given")
    elif form in candidates:
        chosen, reason = form, "asked for"
    else:
        raise ValueError(f"form {form!r} has more parameters than there are sizes "
                         f"({n.size}): measure more sizes or fix omega")
    best = candidates[chosen]
    if best.omega_fitted and best.omega <= OMEGA_RANGE[0] * (1.0 + OMEGA_AT_BOUND):
        flat = candidates["constant"]
        reason += (f"; ω ran to its lower bound {OMEGA_RANGE[0]:g}: these sizes resolve no "
                   f"trend, and the interval is that of a drift without end (the constant "
                   f"fits with χ² p = {flat.p_value:.2g}: {flat.value:.4g})")
    inflation = math.sqrt(best.chi2 / best.dof) if best.dof > 0 else 1.0
    rng = np.random.default_rng(seed)
    draws = x + rng.standard_normal((n_draws, n.size)) * sigmas * max(1.0, inflation)
    refitted = _fit_form(n, draws, 1.0 / sigmas ** 2, chosen,
                         None if best.omega_fitted else (best.omega if chosen == "power"
                                                         else omega))[0]
    tail = 50.0 * (1.0 - confidence)
    interval = (float(np.percentile(refitted, tail)), float(np.percentile(refitted, 100 - tail)))
    candidates[chosen] = replace(best, interval=interval)
    return Extrapolation(sizes=n, values=x, sigmas=sigmas, chosen=candidates[chosen],
                         candidates=candidates, reason=reason)
