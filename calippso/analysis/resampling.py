"""Bootstrap resamples of a fit window, reduced to the sums a likelihood fit needs.

A maximum-likelihood fit of a power law, with or without an exponential cut-off, depends on
the values in its window only through their number, the mean of log x and the mean of x, and
on the window's lower end a (the `min_count`-th smallest value of the sample;
`calippso.analysis.fits`). `window_sums` gives these for every resample without sorting
the resample: the per-packing sums over the values below the window top are added with the
multiplicity of each packing, and the smallest values, which decide a and the values left
below the window, are found among the `min_count` smallest of each chosen packing. A
resample costs O(packings × min_count) when whole packings are resampled and O(K) for K
values resampled one by one, instead of sorting them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .sample import PooledSample

__all__ = ["WindowSums", "window_sums"]


@dataclass(frozen=True)
class WindowSums:
    """The statistics of one resample's fit window.

    Attributes
    ----------
    n_points : int
        Values in the window (rank ≥ min_count, 0 < x, floor ≤ x ≤ upper).
    mean_log : float
        Mean of log x over them (nan when the window is empty).
    mean_x : float
        Mean of x over them (units of the sample; nan when empty).
    lower : float
        The window's lower end a: the larger of the floor and the min_count-th smallest
        positive value (nan when the resample holds fewer than min_count values).
    """

    n_points: int
    mean_log: float
    mean_x: float
    lower: float


def window_sums(sample: PooledSample, upper: float, min_count: int, n_resamples: int,
                rng: np.random.Generator, by_packing: bool,
                lower: float = 0.0) -> list[WindowSums]:
    """The window statistics of `n_resamples` bootstrap resamples of `sample`.

    Parameters
    ----------
    sample : PooledSample
        Positive values (a value ≤ 0 counts in the ranks and never lies in a window).
    upper : float
        The window top (units of the sample).
    min_count : int
        The window starts at the `min_count`-th smallest value of the resample.
    n_resamples : int
    rng : numpy.random.Generator
        Draws, per resample, ``rng.integers(0, n, n)``: n = packings when `by_packing`
        (whole packings resampled), n = values otherwise.
    by_packing : bool
    lower : float
        The window's floor: it starts at the larger of `lower` and the `min_count`-th
        smallest positive value of the resample.

    Returns
    -------
    list of WindowSums
        One per resample, in the order drawn.
    """
    if by_packing:
        return _by_packing(sample, upper, min_count, n_resamples, rng, lower)
    return _by_value(sample, upper, min_count, n_resamples, rng, lower)


def _by_value(sample: PooledSample, upper: float, min_count: int, n_resamples: int,
              rng: np.random.Generator, lower: float) -> list[WindowSums]:
    values = sample.values
    k = values.size
    reach = int(np.searchsorted(values, upper, side="right"))   # values ≤ upper: [0, reach)
    low = values[:reach]
    positive = low > 0
    floor = low >= lower
    logs = np.log(np.where(positive, low, 1.0))
    rows = []
    for _ in range(n_resamples):
        drawn = rng.integers(0, k, k)
        copies = np.bincount(drawn[drawn < reach], minlength=reach)
        ranked = np.cumsum(copies)                 # rank of the last copy of each value
        # copies with rank ≥ min_count: the first min_count − 1 draws lie below the window
        kept = np.clip(ranked - (min_count - 1), 0, copies) * positive
        starts = np.flatnonzero(kept)
        start = max(lower, float(low[starts[0]])) if starts.size else float("nan")
        kept = kept * floor
        rows.append(_sums(int(kept.sum()), float(kept @ logs), float(kept @ low), start))
    return rows


def _by_packing(sample: PooledSample, upper: float, min_count: int, n_resamples: int,
                rng: np.random.Generator, lower: float) -> list[WindowSums]:
    values, groups, n_groups = sample.values, sample.groups, sample.n_groups
    inside = (values > 0) & (values <= upper) & (values >= lower)
    count = np.bincount(groups[inside], minlength=n_groups)
    log_sum = np.bincount(groups[inside], weights=np.log(values[inside]), minlength=n_groups)
    x_sum = np.bincount(groups[inside], weights=values[inside], minlength=n_groups)
    heads = _smallest_per_group(values, groups, n_groups, min_count)
    rows = []
    for _ in range(n_resamples):
        copies = np.bincount(rng.integers(0, n_groups, n_groups), minlength=n_groups)
        pooled_heads = np.repeat(heads, copies, axis=0).ravel()
        smallest = np.sort(np.partition(pooled_heads, min_count - 1)[:min_count])
        ranked_first = float(smallest[-1])
        if not ranked_first > 0:    # fewer than min_count values, or zeros in the ranks
            rows.append(WindowSums(0, float("nan"), float("nan"), float("nan")))
            continue
        below = smallest[:-1]       # ranked below the window, though perhaps inside it
        below = below[(below > 0) & (below <= upper) & (below >= lower)]
        rows.append(_sums(int(copies @ count) - below.size,
                          float(copies @ log_sum) - float(np.log(below).sum()),
                          float(copies @ x_sum) - float(below.sum()),
                          max(lower, ranked_first)))
    return rows


def _smallest_per_group(values: np.ndarray, groups: np.ndarray, n_groups: int,
                        min_count: int) -> np.ndarray:
    """The `min_count` smallest values of each group, shape (n_groups, min_count), padded
    with +inf (`values` ascending)."""
    order = np.argsort(groups, kind="stable")     # by group, ascending within each group
    grouped = groups[order]
    rank = np.arange(grouped.size) - np.searchsorted(grouped, grouped)
    first = rank < min_count
    heads = np.full((n_groups, min_count), np.inf)
    heads[grouped[first], rank[first]] = values[order][first]
    return heads


def _sums(count: int, log_sum: float, x_sum: float, lower: float) -> WindowSums:
    if count <= 0:
        return WindowSums(0, float("nan"), float("nan"), lower)
    return WindowSums(count, log_sum / count, x_sum / count, lower)
