"""Numba cell lists in d dimensions, used to build Verlet neighbour lists.

Why it exists beside `calippso.geometry.neighbors`: the event-driven, force-biased and soft-sphere
loops rebuild their lists from inside compiled Numba code, which cannot call scipy's tree.

A cubic or rectangular box is cut into n_μ ≥ 1 cells per direction, each at least as
wide as the search radius, so that every pair within the radius lies in the same or in
adjacent cells. The adjacent-cell offsets are generated for the dimension at hand (3^d of them,
fewer in a direction with only one or two cells, so that no cell is visited twice). Along an
axis closed by walls (not periodic) the cells do not wrap: the neighbours of an edge cell
lie on one side only, and pairs meet without the minimum image.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .periodic import image_component, inverse_sides

__all__ = ["cell_offsets", "verlet_lists"]


@njit(cache=True)
def cell_offsets(n_cells: np.ndarray, periodic: np.ndarray) -> np.ndarray:
    """Offsets of the neighbouring cells, each visited once.

    Parameters
    ----------
    n_cells : ndarray of int64, shape (d,)
        Cells per direction.
    periodic : ndarray, shape (d,), bool
        Periodic axes; along the others the offsets are {−1, 0, 1} whenever there are two
        cells or more (the caller skips the cells beyond the edges).

    Returns
    -------
    ndarray of int64, shape (K, d)
        Offsets in {−1, 0, 1} (3 or more cells), {0, 1} (2 periodic cells) or {0} (1 cell)
        per direction.
    """
    d = n_cells.shape[0]
    choices = np.empty(d, dtype=np.int64)
    total = 1
    for mu in range(d):
        choices[mu] = min(n_cells[mu], 3) if periodic[mu] or n_cells[mu] == 1 else 3
        total *= choices[mu]
    offsets = np.empty((total, d), dtype=np.int64)
    for k in range(total):
        rest = k
        for mu in range(d):
            digit = rest % choices[mu]
            rest //= choices[mu]
            offsets[k, mu] = digit - 1 if choices[mu] == 3 else digit
    return offsets


@njit(cache=True)
def verlet_lists(x: np.ndarray, box: np.ndarray, diameters: np.ndarray, skin: float,
                 periodic: np.ndarray):
    """Every pair with |r_ij| < σ_ij + skin, as per-particle neighbour lists (CSR).

    Parameters
    ----------
    x : ndarray, shape (N, d)
        Positions, wrapped into [0, L) along the periodic axes; along the others a position
        outside [0, L) is counted in the edge cell.
    box : ndarray, shape (d,)
        Box sides L_μ; along a periodic axis the largest search radius max σ + skin must be
        below L_μ / 2.
    diameters : ndarray, shape (N,)
        Current diameters σ_i.
    skin : float
        Extra distance beyond contact, in length units (≥ 0).
    periodic : ndarray, shape (d,), bool
        Periodic axes: the cells wrap and pairs meet by the minimum image along these only.

    Returns
    -------
    start : ndarray of int64, shape (N + 1,)
        Neighbours of i are ``neighbours[start[i]:start[i + 1]]``.
    neighbours : ndarray of int64, shape (2 M,)
        Each of the M pairs appears in both lists.
    """
    n, d = x.shape
    reach = diameters.max() + skin
    n_cells = np.empty(d, dtype=np.int64)
    width = np.empty(d)
    stride = np.empty(d, dtype=np.int64)
    total = 1
    for mu in range(d):
        n_cells[mu] = max(1, int(box[mu] / reach))
        width[mu] = box[mu] / n_cells[mu]
        stride[mu] = total
        total *= n_cells[mu]
    # Counting sort of the particles by cell.
    cell = np.empty(n, dtype=np.int64)
    coords = np.empty((n, d), dtype=np.int64)
    counts = np.zeros(total + 1, dtype=np.int64)
    for i in range(n):
        c = 0
        for mu in range(d):
            k = int(x[i, mu] / width[mu])
            k = min(max(k, 0), n_cells[mu] - 1)
            coords[i, mu] = k
            c += k * stride[mu]
        cell[i] = c
        counts[c + 1] += 1
    for c in range(total):
        counts[c + 1] += counts[c]
    members = np.empty(n, dtype=np.int64)
    fill = counts[:-1].copy()
    for i in range(n):
        members[fill[cell[i]]] = i
        fill[cell[i]] += 1
    offsets = cell_offsets(n_cells, periodic)
    inv = inverse_sides(box, periodic)
    # Pairs i < j within reach of each other.
    capacity = 16 * n
    pair_i = np.empty(capacity, dtype=np.int64)
    pair_j = np.empty(capacity, dtype=np.int64)
    m = 0
    for i in range(n):
        for k in range(offsets.shape[0]):
            c = 0
            for mu in range(d):
                neighbour = coords[i, mu] + offsets[k, mu]
                if not periodic[mu] and (neighbour < 0 or neighbour >= n_cells[mu]):
                    c = -1
                    break
                c += (neighbour % n_cells[mu]) * stride[mu]
            if c < 0:
                continue
            for q in range(counts[c], counts[c + 1]):
                j = members[q]
                if j <= i:
                    continue
                r2 = 0.0
                for mu in range(d):
                    dx = image_component(x[i, mu] - x[j, mu], box[mu], inv[mu])
                    r2 += dx * dx
                cut = 0.5 * (diameters[i] + diameters[j]) + skin
                if r2 < cut * cut:
                    if m == capacity:
                        capacity *= 2
                        grown_i = np.empty(capacity, dtype=np.int64)
                        grown_j = np.empty(capacity, dtype=np.int64)
                        grown_i[:m] = pair_i[:m]
                        grown_j[:m] = pair_j[:m]
                        pair_i, pair_j = grown_i, grown_j
                    pair_i[m] = i
                    pair_j[m] = j
                    m += 1
    start = np.zeros(n + 1, dtype=np.int64)
    for p in range(m):
        start[pair_i[p] + 1] += 1
        start[pair_j[p] + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    neighbours = np.empty(2 * m, dtype=np.int64)
    fill = start[:-1].copy()
    for p in range(m):
        neighbours[fill[pair_i[p]]] = pair_j[p]
        fill[pair_i[p]] += 1
        neighbours[fill[pair_j[p]]] = pair_i[p]
        fill[pair_j[p]] += 1
    return start, neighbours
