"""Shortest distance between spherocylinder shafts (Vega–Lago), and overlap checks.

A spherocylinder i is the set of points within d_i / 2 of its shaft, the segment
r_i + λ u_i with |λ| ≤ l_i / 2 (u_i a unit vector, l_i ≥ 0 the cylinder length). Two
spherocylinders overlap when the shortest distance δ_ij between their shafts is below
(d_i + d_j) / 2. A sphere is the case l = 0.

The kernels take the shaft half-lengths h = l / 2 and the separation of the centres
r = r_j − r_i (already minimum-imaged); they return the squared distance and the positions
λ (on shaft i) and μ (on shaft j) of the closest points r_i + λ u_i and r_j + μ u_j.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from calippso.geometry.periodic import minimum_image

from ..periodic import image_component

__all__ = ["shaft_distance", "min_distance_ratio", "overlapping_pairs"]

#: Below this value of 1 − (u_i·u_j)² the shafts count as (nearly) parallel: the closed-form
#: free minimum divides by it, so its position (and the sign of its excess) is not trusted and
#: all four edges of the parameter rectangle are searched instead.
PARALLEL_TOLERANCE = 1e-6


@numba.njit(cache=True, inline="always")
def _clamp(x: float, h: float) -> float:
    if x > h:
        return h
    if x < -h:
        return -h
    return x


@numba.njit(cache=True, inline="always")
def _distance2(rx, ry, rz, uix, uiy, uiz, ujx, ujy, ujz, lam, mu):
    dx = rx + mu * ujx - lam * uix
    dy = ry + mu * ujy - lam * uiy
    dz = rz + mu * ujz - lam * uiz
    return dx * dx + dy * dy + dz * dz


@numba.njit(cache=True)
def segment_distance2(rx, ry, rz, uix, uiy, uiz, ujx, ujy, ujz, hi, hj):
    """Squared shortest distance between two segments (Vega–Lago), scalar arguments.

    Parameters
    ----------
    rx, ry, rz : float
        r = r_j − r_i, the separation of the segment centres (minimum image), in length units.
    uix, uiy, uiz, ujx, ujy, ujz : float
        Unit axes u_i and u_j.
    hi, hj : float
        Half-lengths l_i / 2 and l_j / 2 (≥ 0; 0 for a sphere).

    Returns
    -------
    (float, float, float)
        δ² (length²), λ ∈ [−hi, hi] and μ ∈ [−hj, hj]: the closest points are r_i + λ u_i
        and r_j + μ u_j.

    Notes
    -----
    |r + μ u_j − λ u_i|² is a convex quadratic in (λ, μ). Its free minimum is
    λ0 = (r·u_i − c r·u_j) / (1 − c²), μ0 = (c r·u_i − r·u_j) / (1 − c²), c = u_i·u_j. When it
    lies outside the rectangle |λ| ≤ hi, |μ| ≤ hj, the constrained minimum lies on an edge whose
    bound (λ0 or μ0) is exceeded, on the side of the excess (Vega & Lago 1994). On an edge the
    other coordinate is the clamped 1-d minimiser. Vega and Lago pick the edge with the larger
    excess; we evaluate every exceeded edge and keep the closer one, which is exact. For
    (nearly) parallel shafts, 1 − c² < `PARALLEL_TOLERANCE`, the free minimum is ill-conditioned
    (exactly parallel shafts have a line of minimisers): all four edges are evaluated, and the
    free minimum too when it falls inside (its error along the flat valley costs only O(1 − c²)).
    """
    rui = rx * uix + ry * uiy + rz * uiz
    ruj = rx * ujx + ry * ujy + rz * ujz
    c = uix * ujx + uiy * ujy + uiz * ujz
    cc = 1.0 - c * c
    best = np.inf
    best_lam = 0.0
    best_mu = 0.0
    check_lam_lo = check_lam_hi = check_mu_lo = check_mu_hi = True
    if cc > 0.0:
        lam = (rui - c * ruj) / cc
        mu = (c * rui - ruj) / cc
        inside = abs(lam) <= hi and abs(mu) <= hj
        if inside:
            best = _distance2(rx, ry, rz, uix, uiy, uiz, ujx, ujy, ujz, lam, mu)
            best_lam, best_mu = lam, mu
        if cc >= PARALLEL_TOLERANCE:
            if inside:
                return best, best_lam, best_mu
            check_lam_hi = lam > hi
            check_lam_lo = lam < -hi
            check_mu_hi = mu > hj
            check_mu_lo = mu < -hj
    for side in (-1.0, 1.0):
        if (check_lam_hi and side > 0.0) or (check_lam_lo and side < 0.0):
            lam = side * hi
            mu = _clamp(lam * c - ruj, hj)
            d2 = _distance2(rx, ry, rz, uix, uiy, uiz, ujx, ujy, ujz, lam, mu)
            if d2 < best:
                best, best_lam, best_mu = d2, lam, mu
        if (check_mu_hi and side > 0.0) or (check_mu_lo and side < 0.0):
            mu = side * hj
            lam = _clamp(rui + mu * c, hi)
            d2 = _distance2(rx, ry, rz, uix, uiy, uiz, ujx, ujy, ujz, lam, mu)
            if d2 < best:
                best, best_lam, best_mu = d2, lam, mu
    return best, best_lam, best_mu


@numba.njit(cache=True, inline="always")
def separation(positions, box, inverse, i, j):
    """Minimum image of r_j − r_i (length units) as three components; `inverse` is 1 / box."""
    return (image_component(positions[j, 0] - positions[i, 0], box[0], inverse[0]),
            image_component(positions[j, 1] - positions[i, 1], box[1], inverse[1]),
            image_component(positions[j, 2] - positions[i, 2], box[2], inverse[2]))


@numba.njit(cache=True)
def _all_pairs_ratio(positions, axes, lengths, diameters, box, threshold):
    """Brute force over all pairs: min δ_ij/σ_ij and the pairs with δ_ij/σ_ij < threshold.

    Pairs with δ_ij/σ_ij ≥ max(threshold, 2) are skipped early (the minimum is reported only if
    below that horizon).
    """
    horizon = max(threshold, 2.0)
    n = positions.shape[0]
    inverse = 1.0 / box
    half = 0.5 * lengths
    smallest = np.inf
    found = []
    for i in range(n - 1):
        for j in range(i + 1, n):
            sigma = 0.5 * (diameters[i] + diameters[j])
            reach = half[i] + half[j] + sigma * horizon
            rx, ry, rz = separation(positions, box, inverse, i, j)
            if rx * rx + ry * ry + rz * rz >= reach * reach:
                continue
            d2, _, _ = segment_distance2(rx, ry, rz, axes[i, 0], axes[i, 1], axes[i, 2],
                                         axes[j, 0], axes[j, 1], axes[j, 2], half[i], half[j])
            ratio = math.sqrt(d2) / sigma
            if ratio < smallest:
                smallest = ratio
            if ratio < threshold:
                found.append((i, j))
    return smallest, found


def shaft_distance(center_i, axis_i, length_i: float, center_j, axis_j, length_j: float,
                   box=None) -> tuple[float, float, float]:
    """Shortest distance between the shafts of two spherocylinders.

    Parameters
    ----------
    center_i, center_j : array_like, shape (3,)
        Centres r_i, r_j, in length units.
    axis_i, axis_j : array_like, shape (3,)
        Axes; normalised here (must be non-zero).
    length_i, length_j : float
        Cylinder lengths l ≥ 0 (0 for a sphere), in length units.
    box : array_like, shape (3,) or float, optional
        Periodic box sides; the centres' separation is then taken as its minimum image.

    Returns
    -------
    (float, float, float)
        δ_ij (length units), and λ_i, λ_j: the closest points are r_i + λ_i u_i and
        r_j + λ_j u_j, with |λ| ≤ l / 2.
    """
    r = np.asarray(center_j, dtype=np.float64) - np.asarray(center_i, dtype=np.float64)
    if box is not None:
        r = minimum_image(r, np.broadcast_to(np.asarray(box, dtype=np.float64), (3,)))
    ui = np.asarray(axis_i, dtype=np.float64)
    uj = np.asarray(axis_j, dtype=np.float64)
    for name, axis in (("axis_i", ui), ("axis_j", uj)):
        if axis.shape != (3,) or not np.linalg.norm(axis) > 0:
            raise ValueError(f"{name} must be a non-zero 3-vector, got {axis.tolist()}")
    if length_i < 0 or length_j < 0:
        raise ValueError(f"cylinder lengths must be >= 0, got {length_i} and {length_j}")
    ui = ui / np.linalg.norm(ui)
    uj = uj / np.linalg.norm(uj)
    d2, lam, mu = segment_distance2(r[0], r[1], r[2], ui[0], ui[1], ui[2], uj[0], uj[1], uj[2],
                                    0.5 * float(length_i), 0.5 * float(length_j))
    return math.sqrt(d2), float(lam), float(mu)


def _arrays(packing):
    return (np.ascontiguousarray(packing.positions), np.ascontiguousarray(packing.axes),
            np.ascontiguousarray(packing.lengths), np.ascontiguousarray(packing.diameters),
            np.ascontiguousarray(packing.box))


def min_distance_ratio(packing) -> float:
    """Smallest δ_ij / σ_ij over all pairs, with the exact shaft distance (all pairs checked).

    Parameters
    ----------
    packing : SpherocylinderPacking

    Returns
    -------
    float
        ≥ 1 when no two particles overlap (1 for touching ones); inf if no pair has
        δ_ij < 2 σ_ij.
    """
    smallest, _ = _all_pairs_ratio(*_arrays(packing), 1.0)
    return float(smallest)


def overlapping_pairs(packing, tolerance: float = 0.0) -> np.ndarray:
    """Pairs (i < j) whose shafts are closer than (1 − tolerance) σ_ij (all pairs checked).

    Parameters
    ----------
    packing : SpherocylinderPacking
    tolerance : float
        Relative tolerance on σ_ij (0: any overlap counts).

    Returns
    -------
    ndarray of int, shape (M, 2)
    """
    _, found = _all_pairs_ratio(*_arrays(packing), 1.0 - tolerance)
    return np.array(found, dtype=np.int64).reshape(-1, 2)
