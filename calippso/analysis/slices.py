"""Volumes of d-balls cut by a plane or by a coaxial cylinder: the geometry of
`calippso.analysis.layering`.

A plane cut is exact (a regularised incomplete beta function). A cylinder cut integrates the
lens areas of the ball's circular cross-sections over the other d − 2 coordinates by
Gauss–Legendre quadrature (exact in d = 2).
"""

from __future__ import annotations

from math import gamma, pi

import numpy as np
from scipy.special import betainc

__all__ = ["fraction_below", "volume_inside_cylinder", "CYLINDER_QUADRATURE_NODES"]

#: Gauss–Legendre nodes of the integral over the d − 2 coordinates along a cylinder's axis
#: (relative error of the cut volumes about 1e-5 where the cut is tangent to the ball, far
#: less elsewhere).
CYLINDER_QUADRATURE_NODES = 48


def fraction_below(u: np.ndarray, d: int) -> np.ndarray:
    """Share of a d-ball's volume on the side x < u r of a plane, x measured from its centre.

    Parameters
    ----------
    u : ndarray
        Height of the plane over the centre, in units of the radius (any shape; clipped to
        [−1, 1]).
    d : int
        Dimension of the ball.

    Returns
    -------
    ndarray, same shape as `u`
        ½ (1 + sign(u) I_{u²}(½, (d + 1)/2)): 0 below the ball, 1 above it.
    """
    u = np.clip(np.asarray(u, dtype=np.float64), -1.0, 1.0)
    return 0.5 * (1.0 + np.sign(u) * betainc(0.5, 0.5 * (d + 1), u * u))


def _lens_area(offset: np.ndarray, radius: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Area of the intersection of a disc of `radius` centred `offset` from the origin with
    the disc of radius `reach` about the origin (broadcast shapes, length units)."""
    offset, radius, reach = np.broadcast_arrays(offset, radius, reach)
    area = np.zeros(offset.shape)
    inside = offset <= np.abs(reach - radius)
    area[inside] = pi * np.minimum(radius, reach)[inside] ** 2
    crossing = ~inside & (offset < radius + reach)
    D, a, R = offset[crossing], radius[crossing], reach[crossing]
    cos_a = np.clip((D * D + a * a - R * R) / (2 * D * a), -1.0, 1.0)
    cos_r = np.clip((D * D + R * R - a * a) / (2 * D * R), -1.0, 1.0)
    kite = (-D + a + R) * (D + a - R) * (D - a + R) * (D + a + R)
    area[crossing] = (a * a * np.arccos(cos_a) + R * R * np.arccos(cos_r)
                      - 0.5 * np.sqrt(np.maximum(kite, 0.0)))
    return area


def volume_inside_cylinder(offset: np.ndarray, radius: np.ndarray, reach: np.ndarray,
                           d: int) -> np.ndarray:
    """Volume of each d-ball within distance `reach` of a cylinder's axis.

    The cylinder's circle lies in two of the d axes; its axis spans the other d − 2.

    Parameters
    ----------
    offset : ndarray, shape (N,)
        Distance of each ball's centre from the cylinder's axis (length units).
    radius : ndarray, shape (N,)
        Ball radii (length units).
    reach : ndarray, shape (K,)
        Radii of the coaxial cylinders (length units, ≥ 0).
    d : int
        Dimension (≥ 2).

    Returns
    -------
    ndarray, shape (N, K)
        The cut volumes (length^d); V_d(radius) where the cylinder holds the whole ball.
    """
    offset = np.asarray(offset, dtype=np.float64)[:, None, None]
    radius = np.asarray(radius, dtype=np.float64)[:, None, None]
    reach = np.asarray(reach, dtype=np.float64)[None, :, None]
    k = d - 2
    if k == 0:
        return _lens_area(offset, radius, reach)[:, :, 0]
    # the ball's cross-section at distance t = r sin(angle) along the axis is a disc of
    # radius r cos(angle); the (k − 1)-sphere of such points has area S t^(k − 1)
    nodes, weights = np.polynomial.legendre.leggauss(CYLINDER_QUADRATURE_NODES)
    angle = 0.25 * pi * (nodes + 1.0)
    sphere_area = 2.0 * pi ** (k / 2) / gamma(k / 2)
    jacobian = (0.25 * pi * weights * sphere_area * np.sin(angle) ** (k - 1)
                * np.cos(angle))[None, None, :]
    discs = _lens_area(offset, radius * np.cos(angle)[None, None, :], reach)
    return np.sum(jacobian * radius ** k * discs, axis=2)
