"""The last stage in a deformable box: the forces with an isotropic stress, the stress tensor
and the strict certificate, and the `JammingResult`.

A network certified by the strict Newton stage keeps its forces when they balance at the
final geometry. Otherwise the last LP's network and forces are projected onto the forces in
equilibrium with an isotropic stress at the final positions (`balanced_network`), and a run
that converged is tested for strict jamming (`calippso.deformable.strict_category`). Round-off
overlaps are shrunk away first; forces are scaled to mean 1.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from scipy.optimize import linprog
from scipy.sparse.linalg import lsmr

from ..certification.strict_newton import NEAR_CONTACT
from ..deformable import (certificate_note, contact_stress, smallest_gap, strain_coefficients,
                          strict_category, strict_zero_modes)
from ..geometry.contact_network import (GEOMETRIC_CONTACT_GAP, ROUNDOFF_SHRINK_MARGIN,
                                        ContactNetwork)
from ..geometry.contacts import force_balance, isostaticity_gap
from ..geometry.packing import Packing
from ..geometry.rattlers import remove_rattlers
from ..geometry.sheared_search import sheared_pairs_within
from ..history import History, StopReason, status_sentence
from ..result import JammingResult
from ..step import Step
from .finish import final_notes
from .state import LoopState, Run

__all__ = ["strict_finish", "balanced_network"]

#: Tolerances, condition limit (none) and iteration cap of the least-squares projection of
#: the final forces, and its largest number of passes: each pass projects the last one's
#: round-off, the residual does not fall steadily, and the best pass is kept (at N = 1024 in
#: d = 3, one pass leaves a net force of 1e-12 to 2e-12 of the mean force, the best of five
#: 1e-13 to 7e-13).
LSMR_TOLERANCE = 1e-16
LSMR_CONDITION_LIMIT = 1e20
LSMR_ITERATIONS = 100_000
PROJECTION_PASSES = 5
#: The passes stop once the largest residual is below this fraction of the mean force.
PROJECTION_TARGET = 1e-14


def strict_finish(run: Run, state: LoopState, network: ContactNetwork, reason: StopReason,
                  last: Step | None) -> JammingResult:
    """The result of a deformable run that stopped at `state` with `network`, for `reason`;
    `last` is the last LP (its network is the fallback of a Newton network whose forces do
    not balance at the final geometry, its duals the strain certificate of the notes)."""
    history, settings = run.history, run.settings
    gap = smallest_gap(state.positions, state.diameters, state.cell)
    diameters = state.diameters
    if gap < 0:
        diameters = diameters * (1.0 + gap) * (1.0 - ROUNDOFF_SHRINK_MARGIN)
        history.note(f"diameters scaled by 1 - {-gap:.1e} to remove round-off overlaps")
    packing = Packing.sheared(state.positions * run.scale, diameters * run.scale,
                              state.cell * run.scale)
    certified = False
    if not network.from_lp:
        i, j, rattlers = network.i, network.j, network.rattlers
        forces = network.forces / network.forces.mean()
        balance = _balance_of(packing, i, j, forces, rattlers)
        certified = balance <= settings.balance_tolerance
        if reason.jammed:
            reason = reason if certified else StopReason.CONVERGED
    if not certified:
        fallback = network if last is None or network.from_lp else last.network()
        i, j, forces, rattlers, balance = balanced_network(packing, fallback.i, fallback.j,
                                                           fallback.forces, history)
    vectors = packing.minimum_image(packing.positions[i] - packing.positions[j])
    stress = contact_stress(vectors, forces, packing.volume)
    n_stable = int(rattlers.size - rattlers.sum())
    gap_count = isostaticity_gap(i.shape[0], n_stable, run.d, strict_zero_modes(run.d))
    if last is not None:
        history.note(certificate_note(last.lp, last.solution, stress))
    category = None
    if certified:
        category = "strict"
        history.note("strictly jammed: positive forces in balance with an isotropic stress, "
                     "and a non-singular Jacobian of the strict contact equations")
    elif reason == StopReason.CONVERGED:
        if n_stable == 0 or gap_count < 0 or balance > settings.balance_tolerance:
            reason = StopReason.NOT_RIGID
        else:
            category = strict_category(packing, i, j, forces, rattlers, history)
            if category is not None and category != "strict":
                reason = StopReason.NOT_RIGID
    notes = final_notes(run, reason)
    return JammingResult(
        packing=packing, contacts=np.stack([i, j], axis=1).astype(np.int64),
        forces=forces, rattlers=rattlers, converged=reason.jammed,
        status=status_sentence(reason, history.lps_solved, history.last_step(), n_stable,
                               gap_count, notes),
        iterations=history.lps_solved, history=history.to_array(),
        wall_time=history.elapsed(), force_balance=balance,
        dual_normalization=np.nan if last is None else last.normalization,
        solver=network.solver, stop_reason=reason, notes=notes, box_mode="deformable",
        stress=stress, category=category)


def balanced_network(packing: Packing, i: np.ndarray, j: np.ndarray, forces: np.ndarray,
                     history: History):
    """The contact network and forces at the final geometry.

    The last LP's contacts and forces, projected onto the forces in equilibrium with an
    isotropic stress at the final positions (`_balanced_forces`). At a degenerate optimum
    (a crystal: the vertex puts its duals on too few rows, the network looks hypostatic),
    the touching pairs (h < `GEOMETRIC_CONTACT_GAP`) with the balanced forces nearest to
    uniform replace it, when those are all positive.

    Returns
    -------
    (i, j, forces of mean 1, rattlers, force balance)
    """
    n, d = packing.n, packing.d
    rattlers, kept = remove_rattlers(n, d, i, j)
    i, j, forces = i[kept], j[kept], forces[kept]
    balanced = _balanced_forces(packing, i, j, forces, rattlers)
    n_stable = int(n - rattlers.sum())
    if n_stable == 0 or isostaticity_gap(i.shape[0], n_stable, d, strict_zero_modes(d)) < 0:
        close = sheared_pairs_within(packing.positions, packing.diameters, packing.lattice,
                                     float(packing.diameters.max()) * (1.0 + NEAR_CONTACT))
        touching = close.subset(close.gaps < GEOMETRIC_CONTACT_GAP)
        t_rattlers, t_kept = remove_rattlers(n, d, touching.i, touching.j)
        ti, tj = touching.i[t_kept], touching.j[t_kept]
        if (int(n - t_rattlers.sum()), ti.shape[0]) > (n_stable, i.shape[0]):
            uniform = _balanced_forces(packing, ti, tj, np.ones(ti.shape[0]), t_rattlers)
            if uniform is not None:
                history.note(f"contacts taken from the touching pairs (h < "
                             f"{GEOMETRIC_CONTACT_GAP:g}): the LP duals are degenerate here; "
                             f"forces are the balanced, isotropic ones nearest to uniform")
                i, j, rattlers, balanced = ti, tj, t_rattlers, uniform
    if balanced is None:
        mean = float(forces.mean()) if forces.size else 1.0
        balance = _balance_of(packing, i, j, forces, rattlers)
        if i.shape[0]:
            history.note(f"no positive forces balance the network with an isotropic stress at "
                         f"the final positions: the last LP's forces are kept (force balance "
                         f"{balance:.1e}), no certificate")
        return i, j, forces / mean, rattlers, balance
    forces = balanced / balanced.mean()
    return i, j, forces, rattlers, _balance_of(packing, i, j, forces, rattlers)


def _equilibrium(packing: Packing, i: np.ndarray, j: np.ndarray) -> tuple[sp.csr_matrix,
                                                                          np.ndarray]:
    """The matrix whose null space holds the forces f in equilibrium on every particle with
    an isotropic stress: d rows per particle (Σ f n), then the deviatoric stress (the strain
    columns but the trace, `calippso.deformable.strain_coefficients`); and the unit
    normals."""
    n, d = packing.n, packing.d
    vectors = packing.minimum_image(packing.positions[i] - packing.positions[j])
    distances = np.linalg.norm(vectors, axis=1)
    normals = vectors / distances[:, None]
    m = i.shape[0]
    coordinate = np.arange(d)
    rows = np.concatenate([(i[:, None] * d + coordinate).ravel(),
                           (j[:, None] * d + coordinate).ravel()])
    columns = np.concatenate([np.repeat(np.arange(m), d)] * 2)
    values = np.concatenate([normals.ravel(), -normals.ravel()])
    balance = sp.csr_matrix((values, (rows, columns)), shape=(n * d, m))
    deviatoric = sp.csr_matrix(strain_coefficients(vectors, distances)[:, :-1].T)
    return sp.vstack([balance, deviatoric]).tocsr(), normals


def _balanced_forces(packing: Packing, i, j, forces, rattlers) -> np.ndarray | None:
    """Positive forces in equilibrium with an isotropic stress at the packing's geometry:
    those nearest to `forces` (least squares), or, when one of those is not positive, the
    point towards the forces whose smallest is largest (an LP) where the smallest force
    reaches half that largest value; None when no positive such forces exist."""
    if not i.shape[0]:
        return None
    matrix, _ = _equilibrium(packing, i, j)
    nearest = _projected(matrix, forces)
    if nearest.min() > 0:
        return nearest
    m = i.shape[0]
    # variables (f, t): maximise t subject to A f = 0, Σ f = m, f ≥ t
    equalities = sp.vstack([sp.hstack([matrix, sp.csr_matrix((matrix.shape[0], 1))]),
                            sp.csr_matrix(np.append(np.ones(m), 0.0)[None, :])]).tocsr()
    answer = linprog(np.append(np.zeros(m), -1.0), A_eq=equalities,
                     b_eq=np.append(np.zeros(matrix.shape[0]), float(m)),
                     A_ub=sp.hstack([-sp.identity(m), np.ones((m, 1))]).tocsr(),
                     b_ub=np.zeros(m), bounds=[(0, None)] * m + [(None, None)],
                     method="highs")
    if answer.status != 0 or not answer.x[-1] > 0:
        return None
    widest, smallest = answer.x[:m], float(answer.x[-1])
    nearest *= m / nearest.sum()
    # the largest share of `nearest` with every force at least half the LP's smallest one
    below = nearest < 0.5 * smallest
    share = np.min((widest[below] - 0.5 * smallest) / (widest[below] - nearest[below]),
                   initial=1.0)
    blended = _projected(matrix, share * nearest + (1.0 - share) * widest)
    return blended if blended.min() > 0 else None


def _projected(matrix: sp.csr_matrix, forces: np.ndarray) -> np.ndarray:
    """`forces` projected onto the null space of `matrix` (least squares, LSMR run to the
    machine's precision): up to `PROJECTION_PASSES` passes, each projecting the last one's
    round-off; the pass with the smallest largest residual |matrix @ forces| relative to the
    mean force is returned (the passes stop once it is below `PROJECTION_TARGET`)."""
    transposed = matrix.T.tocsr()
    best, smallest = forces, float("inf")
    for _ in range(PROJECTION_PASSES):
        correction = lsmr(transposed, forces, atol=LSMR_TOLERANCE, btol=LSMR_TOLERANCE,
                          conlim=LSMR_CONDITION_LIMIT, maxiter=LSMR_ITERATIONS)[0]
        forces = forces - transposed @ correction
        scale = abs(float(forces.mean())) or 1.0
        residual = float(np.abs(matrix @ forces).max(initial=0.0)) / scale
        if residual < smallest:
            best, smallest = forces, residual
        if smallest < PROJECTION_TARGET:
            break
    return best


def _balance_of(packing: Packing, i, j, forces, rattlers) -> float:
    """max over stable particles of |Σ f n| / mean force, at the packing's geometry."""
    if not i.shape[0]:
        return 0.0
    _, normals = _equilibrium(packing, i, j)
    return force_balance(packing.n, i, j, normals, forces, ~rattlers)
