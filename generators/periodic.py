"""The Numba twins of `calippso.periodic`: its scalar kernels compiled for the inner loops.

The kernels are written once, in `calippso.periodic` (which imports no numba); this module
only compiles them, inlined where they are called, and adds the in-place array loop that
wraps every position.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from calippso import periodic

__all__ = ["image_component", "wrap_coordinate", "wrap_into_box"]

image_component = njit(cache=True, inline="always")(periodic.image_component)
wrap_coordinate = njit(cache=True, inline="always")(periodic.wrap_coordinate)


@njit(cache=True)
def wrap_into_box(x: np.ndarray, box: np.ndarray) -> None:
    """Wrap positions into [0, L) in place (`wrap_coordinate` on every coordinate).

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Positions (length units), overwritten.
    box : ndarray, shape (d,)
        Box sides L_μ (length units).
    """
    for i in range(x.shape[0]):
        for mu in range(x.shape[1]):
            x[i, mu] = wrap_coordinate(x[i, mu], box[mu])
