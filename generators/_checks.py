"""Input validation shared by the generators: one place, errors that name the bad argument."""

from __future__ import annotations

import numpy as np

__all__ = ["check_diameters", "check_dimension", "check_positive", "check_phi", "phi_estimate"]


def check_diameters(diameters) -> np.ndarray:
    """Diameters as a float64 (N,) array; ValueError on a wrong shape, NaN/inf or a value ≤ 0."""
    try:
        array = np.array(diameters, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"diameters must be numeric: {error}") from None
    if array.ndim != 1 or array.shape[0] == 0:
        raise ValueError(f"diameters must be a non-empty 1-d array, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError("diameters contain NaN or inf")
    if np.any(array <= 0):
        raise ValueError(
            f"diameters must be > 0; {int(np.count_nonzero(array <= 0))} are non-positive "
            f"(smallest {array.min():g})"
        )
    return array


def check_dimension(d) -> int:
    """The dimension as an int ≥ 2; ValueError otherwise."""
    if d is None or int(d) != d or d < 2:
        raise ValueError(f"dimension d must be an integer >= 2, got d = {d!r}")
    return int(d)


def check_positive(value, name: str, allow_zero: bool = False) -> float:
    """A finite float > 0 (or ≥ 0); ValueError naming `name` otherwise."""
    value = float(value)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
    return value


def check_phi(phi, name: str = "phi") -> float:
    """A packing fraction in (0, 1); ValueError naming `name` otherwise."""
    phi = float(phi)
    if not (0.0 < phi < 1.0):
        raise ValueError(f"{name} must lie in (0, 1), got {phi!r} (impossible packing fraction)")
    return phi


def phi_estimate(d: int) -> float:
    """Typical random jamming density in dimension d (a default for nominal densities).

    d = 2: 0.84 (bidisperse discs); d ≥ 3: the fit φ ≈ (2.56 d − 2.72)/2^d of Skoge et al.
    (0.62, 0.47, 0.32 at d = 3, 4, 5).
    """
    if d == 2:
        return 0.84
    return (2.56 * d - 2.72) / 2.0**d


#: Relative gap `remove_roundoff_overlap` leaves on the closest pair (a few units of round-off).
ROUNDOFF_MARGIN = 1e-15


def remove_roundoff_overlap(positions: np.ndarray, diameters: np.ndarray,
                            box: np.ndarray) -> tuple[np.ndarray, float]:
    """Scale all diameters down by the (tiny) relative overlap left by round-off, if any.

    The check is an independent periodic KD-tree search (`calippso.neighbors.min_gap`). The
    factor is 1 − (−h + `ROUNDOFF_MARGIN`), not `calippso.neighbors.shrink_to_margin`'s
    (1 + h)(1 − margin), because the two differ in the last bit for some gaps h and the
    generators' outputs must stay the same bit for bit.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (length units).
    diameters : ndarray, shape (N,)
        Diameters (length units).
    box : ndarray, shape (d,)
        Periodic box sides (length units).

    Returns
    -------
    diameters : ndarray, shape (N,)
        The diameters, possibly multiplied by (1 − correction).
    correction : float
        Relative shrink applied (0.0 if no pair overlapped).
    """
    from calippso.neighbors import min_gap

    gap, _ = min_gap(positions, diameters, box)
    if gap >= 0:
        return diameters, 0.0
    correction = -gap + ROUNDOFF_MARGIN
    return diameters * (1.0 - correction), correction
