"""Periodic geometry of a rectangular box: the minimum image and wrapping into the box.

Axes bounded by walls or a cylinder (`calippso.boundaries`) are not periodic: the numpy
functions take an optional mask `periodic` (shape (d,), bool; None means every axis is
periodic, the fast path) and leave the other axes alone. The scalar kernel `image_component`
does the same when given ``inverse = 0`` for such an axis.

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

__all__ = ["minimum_image", "wrap", "displacements", "image_component", "wrap_coordinate"]


def minimum_image(delta: np.ndarray, box: np.ndarray,
                  periodic: np.ndarray | None = None) -> np.ndarray:
    """Minimum-image convention: r − L·round(r/L), componentwise, along periodic axes.

    Parameters
    ----------
    delta : ndarray, shape (..., d)
        Raw separation vectors r_i − r_j (length units).
    box : ndarray, shape (d,)
        Box sides L_μ (length units).
    periodic : ndarray, shape (d,), bool, optional
        Periodic axes (`calippso.boundaries.Boundaries.periodic`); None: all of them.

    Returns
    -------
    ndarray, shape (..., d)
        Separations with every periodic component in [−L/2, L/2]; the other components as
        given.
    """
    if periodic is None or periodic.all():
        return delta - box * np.round(delta / box)
    return delta - np.where(periodic, box, 0.0) * np.round(delta / box)


def wrap(positions: np.ndarray, box: np.ndarray,
         periodic: np.ndarray | None = None) -> np.ndarray:
    """Wrap positions into the half-open box [0, L) along every periodic axis.

    `x % L` can round to exactly L for tiny negative x; such values are set to 0 so that the
    result is strictly inside [0, L) (as `scipy.spatial.cKDTree(boxsize=L)` requires).

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (length units), any real values.
    box : ndarray, shape (d,)
        Box sides L_μ (length units).
    periodic : ndarray, shape (d,), bool, optional
        Periodic axes; None: all of them. The other coordinates are copied unchanged.

    Returns
    -------
    ndarray, shape (N, d)
        A new array with every periodic coordinate in [0, L_μ).
    """
    if periodic is None or periodic.all():
        wrapped = np.mod(positions, box)
        wrapped[wrapped >= box] = 0.0
        return wrapped
    wrapped = np.array(positions, dtype=np.float64)
    axes = np.flatnonzero(periodic)
    inside = np.mod(wrapped[:, axes], box[axes])
    inside[inside >= box[axes]] = 0.0
    wrapped[:, axes] = inside
    return wrapped


def displacements(start: np.ndarray, end: np.ndarray, box: np.ndarray,
                  periodic: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """How far each particle lies from its start, the common translation along the periodic
    axes taken out (it moves no particle relative to another).

    Parameters
    ----------
    start, end : ndarray, shape (N, d)
        The two configurations of the same particles (length units).
    box : ndarray, shape (d,)
        Box sides L_μ (length units).
    periodic : ndarray, shape (d,), bool, optional
        Periodic axes; None: all of them.

    Returns
    -------
    lengths : ndarray, shape (N,)
        |end_i − start_i − t| at the minimum image (length units).
    translation : ndarray, shape (d,)
        The common translation t: the mean minimum-image displacement along the periodic
        axes, 0 along the others.
    """
    delta = minimum_image(end - start, box, periodic)
    mask = np.ones(box.shape[0], dtype=bool) if periodic is None else np.asarray(periodic)
    translation = np.where(mask, delta.mean(axis=0), 0.0)
    return np.linalg.norm(delta - translation, axis=1), translation


def image_component(dx: float, length: float, inverse: float) -> float:
    """One component of the minimum image, dx − L·rint(dx / L), for the Numba loops.

    Parameters
    ----------
    dx : float
        Difference of two coordinates along one axis (length units).
    length : float
        Box side L along that axis (length units).
    inverse : float
        1 / L, computed once by the caller: the loops multiply rather than divide; 0 for an
        axis that is not periodic (the component is then returned unchanged).

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
