"""Periodic geometry of a rectangular box: the minimum image and wrapping into the box.

Axes bounded by walls or a cylinder (`calippso.geometry.boundaries`) are not periodic: the numpy
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

A sheared (triclinic) periodic box is a lattice: a box matrix H, shape (d, d), whose columns
are the box vectors (a point r has fractional coordinates u = H⁻¹ r). `Packing` stores it
upper triangular with a positive diagonal (`triangular_box`), so that its diagonal are the
side lengths and det H = Π H_μμ. Its minimum image (`lattice_minimum_image`) reduces the
lattice first (`reduce_lattice`, LLL) and then checks the 3^d images around the rounded
fractional point; `lattice_wrap` wraps into the cell, `shortest_lattice_vector` bounds the
particle size.
"""

from __future__ import annotations

import numpy as np

__all__ = ["minimum_image", "wrap", "displacements", "image_component", "wrap_coordinate",
           "reduce_lattice", "triangular_box", "lattice_minimum_image", "lattice_wrap",
           "shortest_lattice_vector", "LLL_DELTA"]

#: Lovász's constant of the LLL reduction (`reduce_lattice`): 3/4 is the textbook value;
#: closer to 1 gives a shorter, more orthogonal basis at a few more swaps.
LLL_DELTA = 0.99


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
        Periodic axes (`calippso.geometry.boundaries.Boundaries.periodic`); None: all of them.

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


def reduce_lattice(matrix: np.ndarray) -> np.ndarray:
    """An LLL-reduced basis of the lattice spanned by the columns of `matrix`.

    The reduced basis spans the same lattice (an integer unimodular change of basis) with
    short, nearly orthogonal vectors: the rounded fractional coordinates of a vector then
    lie within one cell of those of its minimum image (`lattice_minimum_image`).

    Parameters
    ----------
    matrix : ndarray, shape (d, d)
        Box vectors as columns (length units), det ≠ 0.

    Returns
    -------
    ndarray, shape (d, d)
        The reduced box vectors, as columns.
    """
    basis = np.array(matrix, dtype=np.float64).T.copy()   # rows are the vectors here
    d = basis.shape[0]
    k = 1
    while k < d:
        for j in range(k - 1, -1, -1):       # size reduction of vector k
            ortho = _gram_schmidt(basis[:j + 1])[j]
            mu = float(basis[k] @ ortho) / float(ortho @ ortho)
            if abs(mu) > 0.5:
                basis[k] -= np.rint(mu) * basis[j]
        ortho = _gram_schmidt(basis[:k + 1])
        previous = float(ortho[k - 1] @ ortho[k - 1])
        mu = float(basis[k] @ ortho[k - 1]) / previous
        if float(ortho[k] @ ortho[k]) >= (LLL_DELTA - mu * mu) * previous:
            k += 1
        else:                                 # Lovász condition fails: swap
            basis[[k - 1, k]] = basis[[k, k - 1]]
            k = max(k - 1, 1)
    return basis.T.copy()


def _gram_schmidt(rows: np.ndarray) -> np.ndarray:
    """The Gram–Schmidt orthogonalisation of the rows (not normalised)."""
    ortho = np.array(rows, dtype=np.float64)
    for k in range(1, ortho.shape[0]):
        for j in range(k):
            ortho[k] -= (rows[k] @ ortho[j]) / (ortho[j] @ ortho[j]) * ortho[j]
    return ortho


def triangular_box(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box `matrix` rotated to upper-triangular form with a positive diagonal.

    Parameters
    ----------
    matrix : ndarray, shape (d, d)
        Box vectors as columns, det > 0.

    Returns
    -------
    triangular : ndarray, shape (d, d)
        R, upper triangular with R_μμ > 0, the same box after the rotation Q.
    rotation : ndarray, shape (d, d)
        Q orthogonal with `matrix` = Q R: a position r in the old frame is Qᵀ r in the new.
    """
    q, r = np.linalg.qr(np.asarray(matrix, dtype=np.float64))
    signs = np.where(np.diag(r) < 0, -1.0, 1.0)
    return signs[:, None] * r, q * signs[None, :]


def _images(d: int) -> np.ndarray:
    """The 3^d integer offsets in {−1, 0, 1}^d, shape (3^d, d)."""
    grids = np.meshgrid(*([np.array([-1.0, 0.0, 1.0])] * d), indexing="ij")
    return np.stack([g.ravel() for g in grids], axis=1)


def lattice_minimum_image(delta: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Minimum image in a sheared periodic box: the shortest r + H n over integer n.

    The lattice is LLL-reduced first; the fractional coordinates of r are rounded, and the
    3^d images around that point are compared. For d ≤ 3 a reduced basis makes this exact;
    above, it is exact for every separation shorter than half the shortest lattice vector
    (the only ones the project's searches ask for).

    Parameters
    ----------
    delta : ndarray, shape (..., d)
        Separations (length units).
    matrix : ndarray, shape (d, d)
        Box vectors as columns.

    Returns
    -------
    ndarray, shape (..., d)
        The shortest image of every separation.
    """
    reduced = reduce_lattice(matrix)
    delta = np.asarray(delta, dtype=np.float64)
    d = reduced.shape[0]
    flat = delta.reshape(-1, d)
    fractional = np.linalg.solve(reduced, flat.T).T
    centred = flat - np.rint(fractional) @ reduced.T
    shifts = _images(d) @ reduced.T                                    # (3^d, d)
    candidates = centred[:, None, :] + shifts[None, :, :]
    best = np.argmin(np.einsum("nkd,nkd->nk", candidates, candidates), axis=1)
    return candidates[np.arange(flat.shape[0]), best].reshape(delta.shape)


def lattice_wrap(positions: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Positions wrapped into the cell {H u : u ∈ [0, 1)^d} of a sheared box.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (length units), any real values.
    matrix : ndarray, shape (d, d)
        Box vectors as columns.

    Returns
    -------
    ndarray, shape (N, d)
        A new array, every fractional coordinate in [0, 1).
    """
    fractional = np.linalg.solve(matrix, np.asarray(positions, dtype=np.float64).T).T
    fractional = np.mod(fractional, 1.0)
    fractional[fractional >= 1.0] = 0.0
    return fractional @ np.asarray(matrix).T


def shortest_lattice_vector(matrix: np.ndarray) -> float:
    """Length of the shortest nonzero vector of the lattice (the shortest column of the
    reduced basis and its sums and differences, exact for d ≤ 3 and a close upper bound
    above)."""
    reduced = reduce_lattice(matrix)
    shifts = _images(reduced.shape[0])
    shifts = shifts[np.any(shifts != 0, axis=1)] @ reduced.T
    return float(np.sqrt(np.einsum("kd,kd->k", shifts, shifts).min()))
