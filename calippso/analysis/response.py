"""Linear response of an isostatic packing to opening one of its contacts.

Lerner, Düring & Wyart (Soft Matter 9, 8252, 2013) call a contact localised when opening it
moves essentially one particle. This module computes that response for every contact.

Unknowns: the displacements u_i of the N_s stable particles (in mean diameters) and the
relative inflation ε of every diameter. To first order, contact k = (i, j), with unit normal
n_k = (r_i − r_j)/|r_i − r_j| and contact distance σ_k, opens by

    n_k · (u_i − u_j) − σ_k ε.

Opening contact k by a unit length while every other contact stays closed, with the centre of
mass fixed (Σ_i u_i = 0), is M + d equations for d N_s + 1 unknowns: a square system exactly
when the packing is isostatic, N_c = d (N_s − 1) + 1. Its solution is the response to opening
contact k. By force balance (Σ_k f_k A_k = 0 over the particle columns of the matrix A), the
inflation part of that response is ε_k = −f_k / Σ_m f_m σ_m: a contact's force is how much the
packing must shrink per unit opening of that contact, which the tests check.

The localisation of a response is the share of its squared displacement Σ_i |u_i|² carried by
the particle that moves most: 1 when one particle moves alone, about 1/N_s when every particle
moves alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..result import JammingResult

__all__ = ["FACTORIZATIONS", "OpeningResponse", "opening_response"]

#: Right-hand sides solved at once (memory: (d N_s + 1) × this many float64).
_BATCH = 256
#: With factorization="auto", up to this many unknowns (d N_s + 1) the system is factorised
#: densely with LAPACK (at most 290 MB), which is faster than SuperLU at these sizes and alone
#: detects a near-singular system (`studies/localization_rules.py --sparse` times both).
_DENSE_LIMIT = 6000
#: Values of `opening_response(factorization=...)`.
FACTORIZATIONS = ("auto", "dense", "sparse")
_FLOPPY = "the contact network has a floppy mode (singular opening equations)"


@dataclass(frozen=True)
class OpeningResponse:
    """Response of a packing to opening each of its contacts, aligned with `result.contacts`.

    Attributes
    ----------
    share : ndarray, shape (M,)
        Share of the squared displacement of the response carried by the particle that moves
        most, in (0, 1].
    mover : ndarray, shape (M,), int64
        That particle (index into the packing).
    inflation : ndarray, shape (M,)
        Relative change ε of the diameters per unit opening of the contact (negative,
        proportional to the contact force).
    reciprocal_condition : float
        LAPACK's estimate of the reciprocal 1-norm condition number of the opening equations
        (dense factorisation; NaN with the sparse one). Systems below (number of unknowns) ×
        machine epsilon are refused as floppy.
    """

    share: np.ndarray
    mover: np.ndarray
    inflation: np.ndarray
    reciprocal_condition: float = float("nan")

    def localized(self, threshold: float = 0.5) -> np.ndarray:
        """Contacts whose response puts more than `threshold` of its weight on one particle.

        Returns
        -------
        ndarray, shape (M,), bool
        """
        if not 0.0 < threshold < 1.0:
            raise ValueError(f"threshold must lie in (0, 1), got {threshold!r}")
        return self.share > threshold


def _response_matrix(result: JammingResult, stable_index: np.ndarray, n_stable: int):
    """The square (M + d, d N_s + 1) sparse matrix of the opening equations (module notes)."""
    from scipy.sparse import csc_matrix

    d = result.d
    contacts = result.contacts
    m = contacts.shape[0]
    vectors = result.contact_vectors
    normals = vectors / np.linalg.norm(vectors, axis=1)[:, None]
    diameters = result.packing.diameters
    sigma = 0.5 * (diameters[contacts[:, 0]] + diameters[contacts[:, 1]])
    i, j = stable_index[contacts[:, 0]], stable_index[contacts[:, 1]]
    axes = np.arange(d)
    contact_rows = np.repeat(np.arange(m), d)
    rows = np.concatenate([contact_rows, contact_rows, np.arange(m),
                           np.repeat(m + axes, n_stable)])
    cols = np.concatenate([(i[:, None] * d + axes).ravel(), (j[:, None] * d + axes).ravel(),
                           np.full(m, d * n_stable),
                           (np.arange(n_stable)[None, :] * d + axes[:, None]).ravel()])
    values = np.concatenate([normals.ravel(), -normals.ravel(), -sigma,
                             np.full(d * n_stable, 1.0 / n_stable)])
    return csc_matrix((values, (rows, cols)), shape=(m + d, d * n_stable + 1))


def _factorised(matrix, dense: bool):
    """A function solving `matrix` x = b for a block b, from one LU factorisation, and the
    reciprocal condition number (NaN on the sparse path).

    Raises ValueError when the matrix is singular to working precision (a floppy mode; the
    dense path checks LAPACK's estimate of the reciprocal condition number).
    """
    from scipy.linalg import lu_factor, lu_solve
    from scipy.linalg.lapack import dgecon
    from scipy.sparse.linalg import splu

    from ..c_stdout import c_stdout_to_stderr

    if dense:
        array = matrix.toarray()
        one_norm = float(np.abs(array).sum(axis=0).max())
        with np.errstate(all="ignore"):
            factor = lu_factor(array, check_finite=False, overwrite_a=True)
        rcond, _ = dgecon(factor[0], one_norm, norm="1")
        if not rcond > matrix.shape[0] * np.finfo(np.float64).eps:
            raise ValueError(f"{_FLOPPY}; reciprocal condition number {rcond:.1e}")
        return (lambda block: lu_solve(factor, block, check_finite=False)), float(rcond)
    try:
        with c_stdout_to_stderr():   # BLAS's complaints on a singular matrix
            factor = splu(matrix)
    except RuntimeError:  # "Factor is exactly singular"
        raise ValueError(_FLOPPY) from None
    return factor.solve, float("nan")


def opening_response(result: JammingResult, *, factorization: str = "auto") -> OpeningResponse:
    """The response to opening each contact of an isostatic packing (module notes).

    Parameters
    ----------
    result : JammingResult
        Isostatic: N_c = d (N_s − 1) + 1.
    factorization : {"auto", "dense", "sparse"}
        LU of the opening equations: LAPACK on the dense matrix, SciPy's SuperLU on the
        sparse one, or ("auto") dense up to 6000 unknowns and sparse above. Both give the same
        response; dense is faster at these sizes, sparse needs less memory for large N. Only
        the dense path detects a singular system that round-off keeps from being exactly
        singular.

    Returns
    -------
    OpeningResponse

    Raises
    ------
    ValueError
        The packing is not isostatic (the opening equations are then not square), its
        contact network is singular (a floppy mode), or its box has walls (wall contacts
        are not in the opening equations yet).

    Notes
    -----
    One LU factorisation of the (M + d)-square matrix, then M solves in batches.
    """
    if factorization not in FACTORIZATIONS:
        raise ValueError(f"factorization must be one of {FACTORIZATIONS}, got {factorization!r}")
    if not result.packing.boundaries.is_periodic:
        raise ValueError(f"the opening response handles periodic packings only, this one has "
                         f"{result.packing.boundaries.describe()}")
    if not result.isostatic:
        raise ValueError(
            f"the opening response needs an isostatic packing; this one has isostaticity gap "
            f"{result.isostaticity_gap} (N_c = {result.n_contacts}, N_s = {result.n_stable})")
    d = result.d
    stable = ~result.rattlers
    n_stable = int(np.count_nonzero(stable))
    stable_index = np.full(result.packing.n, -1, dtype=np.int64)
    stable_index[stable] = np.arange(n_stable)
    stable_particles = np.flatnonzero(stable)
    matrix = _response_matrix(result, stable_index, n_stable)
    dense = factorization == "dense" or (factorization == "auto"
                                         and matrix.shape[0] <= _DENSE_LIMIT)
    solve, reciprocal_condition = _factorised(matrix, dense)
    m = result.n_contacts
    share = np.empty(m)
    mover = np.empty(m, dtype=np.int64)
    inflation = np.empty(m)
    for start in range(0, m, _BATCH):
        batch = np.arange(start, min(m, start + _BATCH))
        openings = np.zeros((m + d, batch.size))
        openings[batch, np.arange(batch.size)] = 1.0
        solution = solve(openings)
        if not np.all(np.isfinite(solution)):
            raise ValueError(_FLOPPY)
        squared = (solution[:-1].reshape(n_stable, d, batch.size) ** 2).sum(axis=1)
        largest = squared.argmax(axis=0)
        share[batch] = squared[largest, np.arange(batch.size)] / squared.sum(axis=0)
        mover[batch] = stable_particles[largest]
        inflation[batch] = solution[-1]
    return OpeningResponse(share=share, mover=mover, inflation=inflation,
                           reciprocal_condition=reciprocal_condition)
