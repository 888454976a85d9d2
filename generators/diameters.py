"""Diameter distributions, all with mean (or smallest) diameter 1 and reproducible seeds."""

from __future__ import annotations

import numpy as np

__all__ = ["monodisperse", "bidisperse", "lognormal"]


def _check_n(n) -> int:
    if int(n) != n or n < 1:
        raise ValueError(f"number of particles n must be a positive integer, got {n!r}")
    return int(n)


def monodisperse(n: int) -> np.ndarray:
    """`n` diameters equal to 1, shape (n,)."""
    return np.ones(_check_n(n))


def bidisperse(n: int, ratio: float = 1.4, fraction: float = 0.5, seed: int = 0) -> np.ndarray:
    """A binary mixture: small diameter 1, large diameter `ratio`, in random order.

    Parameters
    ----------
    n : int
        Number of particles.
    ratio : float
        Large-to-small diameter ratio (≥ 1); 1.4 is the usual 2-d glass former.
    fraction : float
        Number fraction of large particles in [0, 1]; round(fraction · n) particles are large.
    seed : int
        Seed of the shuffle.

    Returns
    -------
    ndarray, shape (n,)
    """
    n = _check_n(n)
    if not ratio >= 1:
        raise ValueError(f"ratio must be >= 1 (large over small diameter), got {ratio!r}")
    if not 0 <= fraction <= 1:
        raise ValueError(f"fraction of large particles must lie in [0, 1], got {fraction!r}")
    diameters = np.ones(n)
    diameters[: int(round(fraction * n))] = ratio
    return np.random.default_rng(seed).permutation(diameters)


def lognormal(n: int, std: float, seed: int = 0) -> np.ndarray:
    """Log-normal diameters with mean 1 and standard deviation `std` (Baranau–Tallarek).

    The underlying normal has variance s² = ln(1 + std²) and mean −s²/2, so the distribution
    has mean 1 and standard deviation `std`; the sample is then divided by its own mean so that
    the mean diameter is exactly 1.

    Parameters
    ----------
    n : int
        Number of particles.
    std : float
        Standard deviation of the diameters (≥ 0), in units of the mean diameter.
    seed : int
        Seed of the random generator.

    Returns
    -------
    ndarray, shape (n,)
    """
    n = _check_n(n)
    if not std >= 0:
        raise ValueError(f"std must be >= 0, got {std!r}")
    s2 = np.log1p(std**2)
    diameters = np.random.default_rng(seed).lognormal(-s2 / 2, np.sqrt(s2), n)
    return diameters / diameters.mean()
