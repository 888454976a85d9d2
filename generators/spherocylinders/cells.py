"""Verlet pair lists for spherocylinders, built with a periodic cell list (Numba).

Why it exists beside `generators.cells`: a rod pair is listed by the distance between the
shafts, not between the centres, which the sphere lists cannot test.

A pair (i, j) is listed when the shortest distance between the shafts is below
σ_ij + skin. The cells have a side of at least the largest possible reach between two
centres, max_i l_i + max_i d_i + skin, so only the 27 neighbouring cells are searched; when the
box holds fewer than 3 cells along some side every pair is tested instead.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .geometry import segment_distance2, separation

__all__ = ["pair_list"]


@numba.njit(cache=True, inline="always")
def _exceeds(squared_distance, bound):
    """Whether a distance given by its square (round-off may make it slightly negative) is at
    least `bound` (≥ 0)."""
    return squared_distance >= bound * bound


@numba.njit(cache=True, inline="always")
def _test_pair(positions, axes, half_lengths, diameters, box, inverse, skin, i, j):
    sigma = 0.5 * (diameters[i] + diameters[j])
    cutoff = sigma + skin
    reach = half_lengths[i] + half_lengths[j] + cutoff
    rx, ry, rz = separation(positions, box, inverse, i, j)
    r2 = rx * rx + ry * ry + rz * rz
    if r2 >= reach * reach:
        return False
    # Cheap lower bounds on the shaft distance (each shaft lies within h of its centre, and a
    # distance to a line is 1-Lipschitz): along u_i, |r·u_i| − h_i − h_j; across u_i, the
    # distance of centre j from the line of shaft i, minus h_j; the same with i and j swapped.
    along_i = rx * axes[i, 0] + ry * axes[i, 1] + rz * axes[i, 2]
    if abs(along_i) - half_lengths[i] - half_lengths[j] >= cutoff:
        return False
    if _exceeds(r2 - along_i * along_i, half_lengths[j] + cutoff):
        return False
    along_j = rx * axes[j, 0] + ry * axes[j, 1] + rz * axes[j, 2]
    if _exceeds(r2 - along_j * along_j, half_lengths[i] + cutoff):
        return False
    d2, _, _ = segment_distance2(rx, ry, rz, axes[i, 0], axes[i, 1], axes[i, 2],
                                 axes[j, 0], axes[j, 1], axes[j, 2],
                                 half_lengths[i], half_lengths[j])
    return d2 < cutoff * cutoff


@numba.njit(cache=True)
def _fill_pairs(positions, axes, half_lengths, diameters, box, skin, out):
    """Write the listed pairs into `out` (M_max, 2); return their number (may exceed M_max)."""
    n = positions.shape[0]
    inverse = 1.0 / box
    capacity = out.shape[0]
    count = 0
    cell_side = 2.0 * half_lengths.max() + diameters.max() + skin
    ncell = np.empty(3, dtype=np.int64)
    for a in range(3):
        ncell[a] = int(math.floor(box[a] / cell_side))
    if ncell.min() < 3:
        for i in range(n - 1):
            for j in range(i + 1, n):
                if _test_pair(positions, axes, half_lengths, diameters, box, inverse, skin, i, j):
                    if count < capacity:
                        out[count, 0] = i
                        out[count, 1] = j
                    count += 1
        return count
    total = ncell[0] * ncell[1] * ncell[2]
    head = np.full(total, -1, dtype=np.int64)
    following = np.full(n, -1, dtype=np.int64)
    cell_of = np.empty((n, 3), dtype=np.int64)
    for i in range(n):
        for a in range(3):
            c = int(math.floor(positions[i, a] / box[a] * ncell[a])) % ncell[a]
            cell_of[i, a] = c
        flat = (cell_of[i, 0] * ncell[1] + cell_of[i, 1]) * ncell[2] + cell_of[i, 2]
        following[i] = head[flat]
        head[flat] = i
    for i in range(n):
        for dx in range(-1, 2):
            cx = (cell_of[i, 0] + dx) % ncell[0]
            for dy in range(-1, 2):
                cy = (cell_of[i, 1] + dy) % ncell[1]
                for dz in range(-1, 2):
                    cz = (cell_of[i, 2] + dz) % ncell[2]
                    j = head[(cx * ncell[1] + cy) * ncell[2] + cz]
                    while j >= 0:
                        if j > i and _test_pair(positions, axes, half_lengths, diameters, box,
                                                inverse, skin, i, j):
                            if count < capacity:
                                out[count, 0] = i
                                out[count, 1] = j
                            count += 1
                        j = following[j]
    return count


def pair_list(positions: np.ndarray, axes: np.ndarray, half_lengths: np.ndarray,
              diameters: np.ndarray, box: np.ndarray, skin: float) -> np.ndarray:
    """Pairs whose shafts are closer than σ_ij + skin.

    Parameters
    ----------
    positions, axes : ndarray, shape (N, 3)
        Centres (anywhere; minimum image is applied) and unit axes.
    half_lengths, diameters : ndarray, shape (N,)
        l_i / 2 and d_i, in length units.
    box : ndarray, shape (3,)
        Periodic box sides.
    skin : float
        Extra distance (length units, ≥ 0).

    Returns
    -------
    ndarray of int64, shape (M, 2)
        Each pair once, i < j.
    """
    positions = np.mod(positions, box)  # the search takes differences of in-box coordinates
    capacity = 16 * positions.shape[0] + 64
    while True:
        out = np.empty((capacity, 2), dtype=np.int64)
        count = _fill_pairs(positions, axes, half_lengths, diameters, box, float(skin), out)
        if count <= capacity:
            return out[:count]
        capacity = count
