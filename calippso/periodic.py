"""Periodic geometry of a rectangular box: the minimum image and wrapping into the box.

Every use of the periodic boundary in the project comes from here, in two forms:

* numpy functions over arrays, `minimum_image` and `wrap`, for the jamming core, the readers
  and the analysis;
* scalar kernels, `image_component` and `wrap_coordinate`, written in plain Python so that
  importing this module never imports numba. `generators.periodic` compiles them with
  ``numba.njit`` for the inner loops of the generators; they run unchanged as Python too.

Both forms take the box as side lengths L_μ > 0 (length units).
"""

from __future__ import annotations

import numpy as np

__all__ = ["minimum_image", "wrap", "image_component", "wrap_coordinate"]


def minimum_image(delta: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Minimum-image convention: r − L·round(r/L), componentwise.

    Parameters
    ----------
    delta : ndarray, shape (..., d)
        Raw separation vectors r_i − r_j (length units).
    box : ndarray, shape (d,)
        Box sides L_μ (length units).

    Returns
    -------
    ndarray, shape (..., d)
        Separations with every component in [−L/2, L/2].
    """
    return delta - box * np.round(delta / box)


def wrap(positions: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Wrap positions into the half-open box [0, L) in every direction.

    `x % L` can round to exactly L for tiny negative x; such values are set to 0 so that the
    result is strictly inside [0, L) (as `scipy.spatial.cKDTree(boxsize=L)` requires).

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (length units), any real values.
    box : ndarray, shape (d,)
        Box sides L_μ (length units).

    Returns
    -------
    ndarray, shape (N, d)
        A new array with every coordinate in [0, L_μ).
    """
    wrapped = np.mod(positions, box)
    wrapped[wrapped >= box] = 0.0
    return wrapped


def image_component(dx: float, length: float, inverse: float) -> float:
    """One component of the minimum image, dx − L·rint(dx / L), for the Numba loops.

    Parameters
    ----------
    dx : float
        Difference of two coordinates along one axis (length units).
    length : float
        Box side L along that axis (length units).
    inverse : float
        1 / L, computed once by the caller: the loops multiply rather than divide.

    Returns
    -------
    float
        The component in [−L/2, L/2].
    """
    return dx - length * np.rint(dx * inverse)


def wrap_coordinate(x: float, length: float) -> float:
    """One coordinate wrapped into [0, L), x − L·floor(x / L), for the Numba loops.

    A value that round-off leaves at L (or just below 0) becomes 0.

    Parameters
    ----------
    x : float
        Coordinate (length units).
    length : float
        Box side L along that axis (length units).

    Returns
    -------
    float
        The coordinate in [0, L).
    """
    wrapped = x - length * np.floor(x / length)
    if wrapped >= length or wrapped < 0.0:
        return 0.0
    return wrapped
