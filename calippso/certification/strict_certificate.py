"""The certificates of a deformable box's final packing: strict jamming, and the strain
certificate of its last LP.

At a strictly jammed point the contact forces are positive and in balance with an isotropic
stress of positive pressure. By Stiemke's theorem no first-order motion of the strict test
(the stable centres and the strain of the periodic axes, at a volume that does not grow) then
opens a contact; when the strict rows have no floppy mode either, the packing is strictly
jammed (docs/theory.md, Jamming categories). `strict_category` reads that certificate
(`floppy_strict_rows`) and falls back on the linear test of `calippso.categories`.

`certificate_note` reads the last LP's own certificate: the strain columns of
`calippso.deformable.strained_lp` say that the LP's contact stress is isotropic and that its
pressure is the volume's multiplier. Both are read by `calippso.stages.strict_finish`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..categories import DENSE_COLUMNS, FLOPPY_EIGENVALUE, jamming_category
from ..deformable import strain_coefficients, strain_count
from ..geometry.contacts import contact_stress, stress_reading
from ..geometry.packing import Packing
from ..geometry.touching import touching_outside_network
from ..geometry.walls import wall_rows_of
from ..history import History
from ..lp import LinearProgram
from ..result import JammingResult
from ..solvers import LPSolution
from .newton import pinned_coordinates

__all__ = ["certificate_note", "strict_category", "floppy_strict_rows"]

#: Column of the trace t = tr ε in a strained LP, counted from the last column (γ's): the
#: trace's reduced cost is the volume's multiplier.
TRACE_FROM_END = 2


def certificate_note(lp: LinearProgram, solution: LPSolution, stress: np.ndarray,
                     periodic: np.ndarray) -> str:
    """The strain certificate of the last LP, as a note of the history.

    The anisotropy of the LP's own contact stress Σ μ r rᵀ/|r| (over every pair row, μ the
    pair rows' duals) on the periodic axes, and its pressure against the volume's multiplier
    (the reduced cost of the trace column); then the anisotropy of the final forces' stress.

    Parameters
    ----------
    lp : LinearProgram
        The last strained LP (`calippso.deformable.strained_lp`).
    solution : LPSolution
        Its solution (duals of the pair rows first).
    stress : ndarray, shape (d, d)
        Contact stress of the final forces (forces of mean 1 per unit volume).
    periodic : ndarray, shape (d,), bool
        The axes the strain acts on (`Boundaries.periodic`).
    """
    pairs = lp.pairs
    lp_stress = contact_stress(pairs.vectors, solution.duals[:len(pairs)], volume=1.0)
    lp_pressure, lp_anisotropy = stress_reading(lp_stress, periodic)
    volume_multiplier = float((lp.matrix.T @ solution.duals)[lp.n_cols - TRACE_FROM_END])
    if not lp_pressure > 0:
        return "strain certificate: the last LP has no contact stress"
    mismatch = abs(volume_multiplier - lp_pressure) / lp_pressure
    final_anisotropy = stress_reading(stress, periodic)[1]
    return (f"strain certificate of the last LP: stress anisotropy {lp_anisotropy:.1e}, volume "
            f"multiplier = virial pressure to {mismatch:.1e}; final forces: stress "
            f"anisotropy {final_anisotropy:.1e}")


def strict_category(packing: Packing, i: np.ndarray, j: np.ndarray, forces: np.ndarray,
                    rattlers: np.ndarray, history: History,
                    wall_contacts: np.ndarray | None = None) -> str | None:
    """The jamming category of the final packing of a deformable run.

    "strict" from the network's own certificate (positive forces, and no floppy mode of the
    strict rows: `floppy_strict_rows`); else the category of the linear test of
    `calippso.categories` on the network and every other pair that touches (a note when it is
    not "strict"); None when that test could not decide (a note says why).

    Parameters
    ----------
    packing : Packing
        The final packing (length units).
    i, j : ndarray, shape (M,), int
        The contacts' particles.
    forces : ndarray, shape (M + K,)
        The pair forces, then those of `wall_contacts` (mean 1).
    rattlers : ndarray, shape (N,), bool
        The rattlers.
    history : History
        The run's history, which takes the notes.
    wall_contacts : ndarray, shape (K, 2), int, optional
        Particle and wall of each wall contact; None: none.
    """
    walls = np.zeros((0, 2), np.int64) if wall_contacts is None else wall_contacts
    if np.all(forces > 0) and not floppy_strict_rows(packing, i, j, rattlers, walls):
        history.note("strictly jammed: positive forces with an isotropic stress, and no "
                     "floppy mode of the strict rows")
        return "strict"
    contacts = np.stack([i, j], axis=1)
    touching = touching_outside_network(packing, contacts, rattlers, walls)
    every = JammingResult(packing=packing, contacts=np.concatenate([contacts, touching.pairs]),
                          forces=np.zeros(0), rattlers=rattlers, converged=False, status="",
                          iterations=0,
                          wall_contacts=np.concatenate([walls, touching.walls]))
    try:
        category = jamming_category(every, up_to="strict")
    except (RuntimeError, ValueError) as error:   # the test's LP failed, or a refusal
        history.note(f"strict jamming not verified: {error}")
        return None
    if category.category == "strict" and not np.all(forces > 0):
        history.note("strictly jammed by the linear test; the balanced forces found on the "
                     "network are not all positive, so they are no certificate of it")
    if category.category != "strict":
        what = "opens contacts" if category.opens_contacts else "keeps every contact closed"
        history.note(f"the linear test of strict jamming found an unjamming motion that "
                     f"{what} (failed class: {category.failed}): not strictly jammed")
    return category.category


def floppy_strict_rows(packing: Packing, i: np.ndarray, j: np.ndarray, rattlers: np.ndarray,
                       wall_contacts: np.ndarray) -> bool:
    """Whether the strict rows of the network have a floppy mode.

    The strict rows are the contacts with the strain columns of the periodic axes, the wall
    contacts and the volume row. A floppy mode is a motion of the stable particles (the
    container's zero modes pinned, `calippso.certification.newton.pinned_coordinates`) and
    the strain that keeps every row at zero. The smallest eigenvalue of AᵀA is zero, up to
    `calippso.categories.FLOPPY_EIGENVALUE` × its mean diagonal, exactly when one exists.

    Parameters
    ----------
    packing : Packing
        The packing (length units).
    i, j : ndarray, shape (M,), int
        The contacts' particles.
    rattlers : ndarray, shape (N,), bool
        The rattlers (no columns).
    wall_contacts : ndarray, shape (K, 2), int
        Particle and wall of each wall contact.
    """
    matrix = _strict_rows(packing, i, j, rattlers, wall_contacts)
    column = _stable_columns(rattlers, packing.d)
    pinned = pinned_coordinates(packing.positions, packing.box, ~rattlers, packing.boundaries)
    held = (column[:, None] + np.arange(packing.d))[pinned]
    free = np.setdiff1d(np.arange(matrix.shape[1]), held)    # the container's zero modes
    return _singular((matrix[:, free].T @ matrix[:, free]).tocsc())


def _singular(stiffness: sp.csc_matrix) -> bool:
    """Whether the smallest eigenvalue of `stiffness` (AᵀA, shape (F, F)) is zero, up to
    `calippso.categories.FLOPPY_EIGENVALUE` × its mean diagonal: computed densely up to
    `calippso.categories.DENSE_COLUMNS` columns, else by shift-invert Lanczos."""
    from scipy.sparse.linalg import eigsh

    scale = float(stiffness.diagonal().mean())
    if stiffness.shape[0] <= DENSE_COLUMNS:
        smallest = float(np.linalg.eigvalsh(stiffness.toarray())[0])
    else:
        smallest = float(eigsh(stiffness, k=1, sigma=-1e-3 * FLOPPY_EIGENVALUE * scale,
                               which="LM", return_eigenvectors=False)[0])
    return smallest <= FLOPPY_EIGENVALUE * scale


def _stable_columns(rattlers: np.ndarray, d: int) -> np.ndarray:
    """The first column of each stable particle's d displacement columns, shape (N,); −1
    for a rattler."""
    stable = np.flatnonzero(~rattlers)
    column = np.full(rattlers.size, -1, dtype=np.int64)
    column[stable] = d * np.arange(stable.size)
    return column


def _strict_rows(packing: Packing, i: np.ndarray, j: np.ndarray, rattlers: np.ndarray,
                 wall_contacts: np.ndarray) -> sp.csr_matrix:
    """The strict rows (`floppy_strict_rows`), shape (M + K + 1, d N_s + d_p(d_p+1)/2): the
    displacements of the stable particles, then the strain variables of
    `calippso.deformable.strained_lp` (the trace last)."""
    d, boundaries = packing.d, packing.boundaries
    k = strain_count(boundaries.n_periodic)
    column = _stable_columns(rattlers, d)
    n_moves = d * int(np.count_nonzero(~rattlers))
    vectors = packing.minimum_image(packing.positions[i] - packing.positions[j])
    distances = np.linalg.norm(vectors, axis=1)
    normals = vectors / distances[:, None]
    walls = wall_rows_of(packing.positions, packing.diameters, packing.box, wall_contacts[:, 0],
                         wall_contacts[:, 1], boundaries.cylinder_axes)
    m, n_walls = i.shape[0], len(walls)
    axis = np.arange(d)
    rows = np.concatenate([np.repeat(np.arange(m), d), np.repeat(np.arange(m), d),
                           m + np.repeat(np.arange(n_walls), d),
                           np.repeat(np.arange(m), k), [m + n_walls]])
    cols = np.concatenate([(column[i][:, None] + axis).ravel(),
                           (column[j][:, None] + axis).ravel(),
                           (column[walls.particle][:, None] + axis).ravel(),
                           np.tile(n_moves + np.arange(k), m), [n_moves + k - 1]])
    values = np.concatenate([normals.ravel(), -normals.ravel(), walls.normals.ravel(),
                             strain_coefficients(vectors, distances,
                                                 boundaries.periodic).ravel(), [-1.0]])
    return sp.csr_matrix((values, (rows, cols)), shape=(m + n_walls + 1, n_moves + k))
