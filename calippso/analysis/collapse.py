"""Finite-size scaling of the gap distribution: the cut-off h_min(N) and the collapse.

A packing of N particles holds about N (Z(h) − z) / 2 gaps below h. Where Z(h) − z ~ h^(1−γ),
its smallest gap therefore lies near h_min(N) ~ N^(−1/(1−γ)), the scale below which a finite
packing has no gaps to show (Charbonneau, Kurchan, Parisi, Urbani & Zamponi 2014 use it to
collapse the gap distributions of several sizes). `gap_cutoff` measures h_min(N) as the
geometric mean over packings of each packing's smallest gap, fits log h_min against log N,
and reads γ off the slope, −1/(1 − γ). `collapsed_cumulative` gives the scaled axes
x = h N^(1/(1−γ)), y = N (Z(h) − z), on which the cumulatives of all sizes fall on one curve
when the finite-size scaling holds: the power law at large x, the cut-off at x ~ 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm

from .sample import PooledSample

__all__ = ["GapCutoff", "collapsed_cumulative", "gap_cutoff"]


@dataclass(frozen=True)
class GapCutoff:
    """The smallest gap of a packing against its size.

    Attributes
    ----------
    sizes : ndarray, shape (S,)
        N, ascending.
    h_min : ndarray, shape (S,)
        Geometric mean over the packings of each packing's smallest gap (dimensionless h).
    interval : ndarray, shape (S, 2)
        Its interval at `confidence` (normal, from the spread of log h_min over packings;
        nan with a single packing).
    packings : ndarray of int, shape (S,)
        Packings at each size.
    slope : float
        d log h_min / d log N (weighted least squares; nan with one size).
    slope_interval : tuple of float
    gamma : float
        1 + 1/slope, the γ for which h_min ~ N^(−1/(1−γ)).
    gamma_interval : tuple of float
    confidence : float
    """

    sizes: np.ndarray
    h_min: np.ndarray
    interval: np.ndarray
    packings: np.ndarray
    slope: float
    slope_interval: tuple[float, float]
    gamma: float
    gamma_interval: tuple[float, float]
    confidence: float

    def scaling_line(self, n: np.ndarray, gamma: float) -> np.ndarray:
        """N^(−1/(1−γ)) through the geometric mean of the measured (N, h_min): the line to
        draw beside h_min(N)."""
        log_n, log_h = np.log(self.sizes), np.log(self.h_min)
        anchor = np.mean(log_h + log_n / (1.0 - gamma))
        return np.exp(anchor - np.log(np.asarray(n, dtype=np.float64)) / (1.0 - gamma))

    def to_dict(self) -> dict:
        """Plain numbers, for JSON."""
        return {"sizes": self.sizes.astype(int).tolist(), "h_min": self.h_min.tolist(),
                "interval": self.interval.tolist(), "packings": self.packings.tolist(),
                "slope": self.slope, "slope_interval": list(self.slope_interval),
                "gamma": self.gamma, "gamma_interval": list(self.gamma_interval),
                "confidence": self.confidence}


def gap_cutoff(gaps_by_size: dict[int, PooledSample], confidence: float = 0.95) -> GapCutoff:
    """h_min(N) per size and the γ of its scaling with N.

    Parameters
    ----------
    gaps_by_size : dict of int to PooledSample
        The pooled gaps (`calippso.analysis.gaps.pooled_gaps`) of the packings of each size
        N, one group per packing.
    confidence : float
        Level of the intervals.

    Returns
    -------
    GapCutoff

    A size whose packings hold no gap below the pooling's largest has h_min nan and no
    packings counted; the slope is fitted on the other sizes.

    Raises
    ------
    ValueError
        No size.
    """
    if not gaps_by_size:
        raise ValueError("gap_cutoff needs the gaps of at least one size")
    z = norm.ppf(0.5 + confidence / 2.0)
    sizes = np.array(sorted(gaps_by_size), dtype=np.float64)
    means, sigmas, counts = [], [], []
    for n in sizes:
        logs = np.log(gaps_by_size[int(n)].minima())
        logs = logs[np.isfinite(logs)]
        means.append(float(np.mean(logs)) if logs.size else float("nan"))
        sigmas.append(float(np.std(logs, ddof=1) / np.sqrt(logs.size)) if logs.size > 1
                      else float("nan"))
        counts.append(logs.size)
    means, sigmas = np.array(means), np.array(sigmas)
    interval = np.exp(np.c_[means - z * sigmas, means + z * sigmas])
    measured = np.isfinite(means)
    slope, slope_interval = _log_slope(np.log(sizes[measured]), means[measured],
                                       sigmas[measured], z)
    gamma_ends = _gamma_of_slopes(*slope_interval)
    return GapCutoff(sizes=sizes, h_min=np.exp(means), interval=interval,
                     packings=np.array(counts), slope=slope,
                     slope_interval=slope_interval, gamma=1.0 + 1.0 / slope,
                     gamma_interval=(gamma_ends[0], gamma_ends[1]),
                     confidence=float(confidence))


def _gamma_of_slopes(low: float, high: float) -> tuple[float, float]:
    """The γ = 1 + 1/slope of the slopes in [low, high]: (1 + 1/high, 1 + 1/low) for
    negative slopes, unbounded below when the interval reaches 0 (a flat h_min(N) means no
    scaling), nan when no slope is negative."""
    if not low < 0:
        return float("nan"), float("nan")
    return (1.0 + 1.0 / high if high < 0 else -math.inf), 1.0 + 1.0 / low


def _log_slope(x: np.ndarray, y: np.ndarray, sigma: np.ndarray,
               z: float) -> tuple[float, tuple[float, float]]:
    """Slope of y on x by weighted least squares (unweighted where a σ is missing), and its
    interval ± z standard errors, inflated by √(χ²/dof) when above 1."""
    nan = float("nan")
    if x.size < 2:
        return nan, (nan, nan)
    weighted = np.all(np.isfinite(sigma) & (sigma > 0))
    w = 1.0 / sigma ** 2 if weighted else np.ones_like(x)
    design = np.c_[np.ones_like(x), x]
    normal = design.T @ (design * w[:, None])
    params = np.linalg.solve(normal, design.T @ (w * y))
    covariance = np.linalg.inv(normal)
    dof = x.size - 2
    chi = float(np.sum(w * (y - design @ params) ** 2))
    if weighted:
        scale = max(1.0, chi / dof) if dof > 0 else 1.0
    else:
        scale = chi / dof if dof > 0 else nan
    error = float(np.sqrt(covariance[1, 1] * scale))
    slope = float(params[1])
    return slope, (slope - z * error, slope + z * error)


def collapsed_cumulative(gaps: PooledSample, n: int,
                         gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """The gap cumulative of packings of N particles on the finite-size scaling axes.

    Parameters
    ----------
    gaps : PooledSample
        Pooled gaps of packings of `n` particles.
    n : int
    gamma : float
        The exponent of the scaling (the reference or a fitted one).

    Returns
    -------
    x, y : ndarray, shape (K,)
        x = h N^(1/(1−γ)), y = N (Z(h) − z).
    """
    h, cumulative = gaps.cumulative()
    return h * float(n) ** (1.0 / (1.0 - gamma)), float(n) * cumulative
