"""Pair search in a sheared periodic box (a box matrix whose columns are the box vectors).

`cKDTree` applies the periodic boundary of a rectangular box only. In a sheared box the
centres are wrapped into the cell of the LLL-reduced lattice (`calippso.geometry.periodic`), the
3^d cells around it are copied, and a plain tree finds every pair within the cutoff
between the centres and the copies. The cutoff must stay below half the shortest lattice
vector, so that no pair has two images within it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .neighbors import Pairs
from .periodic import _images, lattice_wrap, reduce_lattice, shortest_lattice_vector

__all__ = ["sheared_pairs_within", "half_shortest_vector"]


def half_shortest_vector(matrix: np.ndarray) -> float:
    """Half the shortest lattice vector: the largest cutoff with a unique image per pair."""
    return 0.5 * shortest_lattice_vector(matrix)


def sheared_pairs_within(positions: np.ndarray, diameters: np.ndarray, matrix: np.ndarray,
                         cutoff: float) -> Pairs:
    """Every pair whose minimum-image distance is at most `cutoff`, in a sheared box.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (length units, any real values).
    diameters : ndarray, shape (N,)
        Diameters (length units).
    matrix : ndarray, shape (d, d)
        Box vectors as columns.
    cutoff : float
        Largest centre distance (length units), below half the shortest lattice vector and
        below the narrowest width of the reduced cell.

    Returns
    -------
    Pairs
        Sorted by (i, j), i < j, with the minimum-image vectors r_i − r_j.

    Raises
    ------
    ValueError
        If the cutoff reaches half the shortest lattice vector or the reduced cell's width.
    """
    reduced = reduce_lattice(matrix)
    widths = 1.0 / np.linalg.norm(np.linalg.inv(reduced), axis=1)
    limit = min(half_shortest_vector(reduced), float(widths.min()))
    if cutoff >= limit:
        raise ValueError(f"pair cutoff {cutoff:g} reaches the sheared box's limit {limit:g} "
                         f"(half its shortest vector, or its narrowest width)")
    n, d = positions.shape
    inside = lattice_wrap(positions, reduced)
    shifts = _images(d) @ reduced.T
    copies = (inside[None, :, :] + shifts[:, None, :]).reshape(-1, d)
    found = cKDTree(inside).sparse_distance_matrix(cKDTree(copies), cutoff,
                                                   output_type="ndarray")
    i, k = found["i"].astype(np.int64), found["j"].astype(np.int64)
    j = k % n
    keep = i < j
    i, j, k = i[keep], j[keep], k[keep]
    order = np.lexsort((j, i))
    i, j, k = i[order], j[order], k[order]
    vectors = inside[i] - copies[k]
    return Pairs(i, j, vectors, np.linalg.norm(vectors, axis=1),
                 0.5 * (diameters[i] + diameters[j]))
