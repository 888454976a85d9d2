"""The Numba twins of `calippso.geometry.periodic`: its scalar kernels compiled for the inner loops.

The kernels are written once, in `calippso.geometry.periodic` (which imports no numba); this module
only compiles them, inlined where they are called, and adds the in-place array loop that
wraps every position.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from calippso.geometry import periodic

__all__ = ["image_component", "wrap_coordinate", "wrap_into_box", "inverse_sides",
           "all_periodic", "has_walls", "NO_CYLINDER"]

#: The `cylinder` argument of the kernels for a box without a cylinder (with one: its two
#: axes (a, b), `calippso.geometry.boundaries.Boundaries.cylinder_axes`).
NO_CYLINDER = (-1, -1)

image_component = njit(cache=True, inline="always")(periodic.image_component)
wrap_coordinate = njit(cache=True, inline="always")(periodic.wrap_coordinate)


def all_periodic(d: int) -> np.ndarray:
    """The mask of a box periodic along every axis, shape (d,), bool (all True)."""
    return np.ones(d, dtype=np.bool_)


@njit(cache=True)
def inverse_sides(box: np.ndarray, periodic: np.ndarray) -> np.ndarray:
    """1 / L_μ along the periodic axes and 0 along the others, shape (d,): the `inverse`
    argument of `image_component`, which then leaves a bounded axis's component alone.

    Parameters
    ----------
    box : ndarray, shape (d,)
        Box sides L_μ (length units).
    periodic : ndarray, shape (d,), bool
        Periodic axes (`calippso.geometry.boundaries.Boundaries.periodic`).
    """
    inverse = np.zeros(box.shape[0])
    for mu in range(box.shape[0]):
        if periodic[mu]:
            inverse[mu] = 1.0 / box[mu]
    return inverse


@njit(cache=True)
def has_walls(periodic: np.ndarray) -> bool:
    """Whether some axis is not periodic, as a plain loop (inside a parallel=True caller,
    `periodic.all()` may become a threaded reduction, dearer than the whole test).

    Parameters
    ----------
    periodic : ndarray, shape (d,), bool
        Periodic axes.
    """
    for mu in range(periodic.shape[0]):
        if not periodic[mu]:
            return True
    return False


@njit(cache=True)
def wrap_into_box(x: np.ndarray, box: np.ndarray, periodic: np.ndarray) -> None:
    """Wrap positions into [0, L) in place along the periodic axes (`wrap_coordinate`); the
    coordinates along the other axes (walls) are left alone.

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Positions (length units), overwritten.
    box : ndarray, shape (d,)
        Box sides L_μ (length units).
    periodic : ndarray, shape (d,), bool
        Periodic axes.
    """
    for i in range(x.shape[0]):
        for mu in range(x.shape[1]):
            if periodic[mu]:
                x[i, mu] = wrap_coordinate(x[i, mu], box[mu])
