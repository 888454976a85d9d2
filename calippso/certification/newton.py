"""The jamming point of an isostatic contact network, by Newton's method (the solve step).

Once a network is known (read from an LP's duals, or guessed and settled by network first)
and it is isostatic (as many contacts N_c as unknowns d (N_s − 1) + 1), the jamming point
solves the square nonlinear system

    |r_c|² / σ_c² = Γ      for every contact c = (i, j), with r_c = x_i − x_j (fixed image),

in the positions x of the stable particles (one of them pinned) and the common inflation Γ
of the squared diameters. A contact w of particle i with a container wall (`calippso.geometry.walls`)
adds the equation δ_w²/σ_w² = Γ, with δ_w the centre-to-wall distance and σ_w = σ_i/2; in a
box with walls the pinned particle is held along the periodic axes only (a wall holds the
rest), and in a cylinder one more coordinate holds its rotation (`pinned_coordinates`).
Newton's method solves the system to round-off with a few sparse LU solves, where the LP
loop would need many more LPs: the neglected |s|² of its linearisation keeps the LP
displacements from vanishing for a long time.

The answer is certified, not trusted. At the new configuration, with diameters σ √Γ, the
CALiPPSO LP has the optimum s = 0, Γ = 1 (it is the loop's fixed point) when
  - no pair overlaps: s = 0, Γ = 1 is feasible (the caller checks every pair);
  - the self-stress y solving Jᵀ y = (0, …, 0, −1) is positive on every contact: y gives
    LP multipliers that are dual feasible, and with zero gaps on the contacts complementary
    slackness holds, so s = 0, Γ = 1 is optimal;
  - the Jacobian J is non-singular: every optimum keeps all contacts closed (all
    multipliers are positive), and J_x s = 0 then forces s = 0 on the stable particles.
If a check fails, the LP loop goes on. In practice the LP's contact network is the jammed
one only at the very end of the loop: earlier networks, although isostatic, solve to points
with negative forces or new overlaps, which the certificate rejects.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..geometry.boundaries import Boundaries
from ..geometry.packing import minimum_image, wrap
from .sparse_lu import Factors, factorize
from ..geometry.walls import wall_rows_of

__all__ = ["Refinement", "refine_isostatic", "NEWTON_FAILED", "contact_jacobian",
           "network_jacobian", "pinned_coordinates", "contact_equations_jacobian",
           "free_columns", "self_stress"]

#: Newton stops once the largest correction is below this (mean diameters); quadratic
#: convergence then leaves an error far below round-off.
STEP_TOLERANCE = 1e-13
#: Largest residual | |r|²/σ² − Γ | accepted at the end (dimensionless).
RESIDUAL_TOLERANCE = 1e-12
#: Newton also stops when the residual is below this and the corrections stop shrinking:
#: in a large network (N ~ 10⁴) round-off alone leaves corrections of ~1e-12 mean
#: diameters, above `STEP_TOLERANCE`, once the residual is ~1e-14.
ROUNDOFF_RESIDUAL = 1e-13
#: Newton gives up when a correction exceeds this (mean diameters): the start was too far.
MAX_CORRECTION = 0.05
MAX_ITERATIONS = 30
#: Why a network has no Newton solution (`refine_isostatic` returned None), for the notes.
NEWTON_FAILED = "Newton did not converge or the Jacobian is singular"
#: A chord step (old factors) must shrink the correction at least by this factor; a slower
#: one factorises the Jacobian again at the current point (a Newton step).
CHORD_CONTRACTION = 0.25
#: Iterative refinement of the self-stress stops once its residual is below this relative
#: backward error (about 50 units of round-off).
REFINEMENT_TOLERANCE = 1e-14
#: Refinement steps tried before the Jacobian at the solution is factorised itself.
MAX_REFINEMENTS = 8
#: Smallest force, relative to the largest, that certifies a contact (the LP's own contact
#: threshold on the duals, `JamSettings.contact_threshold`, has the same value).
MIN_FORCE_RATIO = 1e-10


@dataclass(frozen=True, eq=False)
class Refinement:
    """A certified jamming point of an isostatic contact network.

    Attributes
    ----------
    positions : ndarray, shape (N, d)
        Positions wrapped into the box (rattlers unmoved), in the caller's units.
    diameters : ndarray, shape (N,)
        Diameters times √Γ.
    forces : ndarray, shape (M,)
        Contact forces f_c = μ_c / 2 in the LP's normalisation Σ μ_c σ_c²/(2|r_c|) = 1, all
        positive, in the order of the contacts given.
    iterations : int
        Newton iterations (corrections applied).
    factorizations : int
        Sparse LU factorisations of the Jacobian (chord steps reuse one).
    sqrt_gamma_minus_1 : float
        √Γ − 1: the diameter growth from the starting configuration.
    max_displacement : float
        Largest displacement component of a stable particle from the start.
    residual : float
        max_c | |r_c|²/σ_c² − Γ | at the end.
    factorization : (Factors, scipy.sparse.csc_matrix) or None
        The last sparse LU made and the Jacobian it factorises (near the solution), for
        solves that follow (`calippso.certification.pivots`); None when every step used given factors.
    wall_forces : ndarray, shape (K,)
        Forces of the wall contacts, in the order given, in the units of `forces`; empty
        without walls.
    """

    positions: np.ndarray
    diameters: np.ndarray
    forces: np.ndarray
    iterations: int
    factorizations: int
    sqrt_gamma_minus_1: float
    max_displacement: float
    residual: float
    factorization: tuple[Factors, sp.csc_matrix] | None = None
    wall_forces: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def positive(self) -> bool:
        """Every contact force (walls included) is positive, above `MIN_FORCE_RATIO` × the
        largest: the network is the jammed one. A force at round-off level is a zero force (a
        contact that could open at no cost), not a certificate."""
        every = np.concatenate([self.forces, self.wall_forces])
        if every.size == 0:
            return True
        return bool(every.min() > MIN_FORCE_RATIO * every.max())


def contact_equations_jacobian(vectors: np.ndarray, inverse_sigma2: np.ndarray,
                               i_cols: np.ndarray, j_cols: np.ndarray,
                               n_unknowns: int) -> sp.csc_matrix:
    """Jacobian of |r_c|²/σ_c² − Γ: 2 r_c/σ_c² on x_i, −2 r_c/σ_c² on x_j, −1 on Γ (the
    last of `n_unknowns` columns).

    `i_cols`, `j_cols` (shape (M, d)) hold the column of every coordinate of each contact's
    two particles (`free_columns`), −1 where it is held fixed (the pinned particle, or the
    wall of a wall contact).
    """
    m = vectors.shape[0]
    gradient = 2.0 * vectors * inverse_sigma2[:, None]
    rows, cols, values = [np.arange(m)], [np.full(m, n_unknowns - 1)], [np.full(m, -1.0)]
    for columns, sign in ((i_cols, 1.0), (j_cols, -1.0)):
        free = columns >= 0
        rows.append(np.nonzero(free)[0])
        cols.append(columns[free])
        values.append(sign * gradient[free])
    return sp.csc_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(m, n_unknowns))


def free_columns(stable: np.ndarray, d: int, pinned: np.ndarray | None = None) -> np.ndarray:
    """The Jacobian column of every coordinate, shape (N, d), numbered in row-major order; −1
    for rattlers and for the `pinned` coordinates (shape (N, d), bool; default: every
    coordinate of the first stable particle)."""
    free = np.repeat(stable[:, None], d, axis=1)
    if pinned is None:
        members = np.flatnonzero(stable)
        if members.size:
            free[members[0]] = False
    else:
        free &= ~pinned
    columns = np.full(free.shape, -1, dtype=np.int64)
    columns[free] = np.arange(int(np.count_nonzero(free)))
    return columns


def pinned_coordinates(positions: np.ndarray, box: np.ndarray, stable: np.ndarray,
                       boundaries: Boundaries) -> np.ndarray:
    """The coordinates held fixed to remove the container's zero modes, shape (N, d), bool.

    The first stable particle is held along the periodic axes (a flat wall or a cylinder
    holds the others). A cylinder also leaves the rotation about its axis: the stable
    particle farthest from that axis is held along the axis of the circle's plane that its
    rotation moves it along most.
    """
    n, d = positions.shape
    pinned = np.zeros((n, d), dtype=bool)
    members = np.flatnonzero(stable)
    if not members.size:
        return pinned
    pinned[members[0]] = boundaries.periodic
    if boundaries.cylinder_axes:
        plane = list(boundaries.cylinder_axes)
        offset = positions[members][:, plane] - 0.5 * box[plane]
        farthest = int(np.argmax(np.einsum("kc,kc->k", offset, offset)))
        # the rotation moves the particle along (−offset_b, offset_a)
        along = plane[0] if abs(offset[farthest, 1]) >= abs(offset[farthest, 0]) else plane[1]
        pinned[members[farthest], along] = True
    return pinned


def network_jacobian(vectors: np.ndarray, sigma: np.ndarray, i: np.ndarray, j: np.ndarray,
                     stable: np.ndarray) -> sp.csr_matrix:
    """The Jacobian of the contact equations of a network, shape (M, d (N_s − 1) + 1).

    Parameters
    ----------
    vectors : ndarray, shape (M, d)
        Separations r_c = x_i − x_j of the contacts (minimum image), length units.
    sigma : ndarray, shape (M,)
        Contact distances σ_c, same units.
    i, j : ndarray, shape (M,), int
        The contacts, between stable particles.
    stable : ndarray, shape (N,), bool
        Non-rattlers; the first stable particle is pinned (it has no columns).
    """
    d = vectors.shape[1]
    n_unknowns = d * (int(np.count_nonzero(stable)) - 1) + 1
    columns = free_columns(stable, d)
    return contact_equations_jacobian(vectors, 1.0 / sigma**2, columns[i], columns[j], n_unknowns).tocsr()


def contact_jacobian(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                     i: np.ndarray, j: np.ndarray, stable: np.ndarray) -> sp.csc_matrix:
    """The Jacobian of the contact equations at a configuration (as `refine_isostatic` builds
    it), shape (M, d (N_s − 1) + 1): for benchmarks of its factorisation.

    Parameters are those of `refine_isostatic`.
    """
    sigma = 0.5 * (diameters[i] + diameters[j])
    vectors = minimum_image(positions[i] - positions[j], box)
    return network_jacobian(vectors, sigma, i, j, stable).tocsc()


def refine_isostatic(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                     i: np.ndarray, j: np.ndarray, stable: np.ndarray,
                     factors: Factors | None = None, *,
                     wall_particle: np.ndarray | None = None, wall: np.ndarray | None = None,
                     boundaries: Boundaries | None = None) -> Refinement | None:
    """Solve the contact equations of an isostatic network and certify the forces.

    Chord steps: the Jacobian is factorised once, at the start, and its factors serve every
    correction while they shrink by at least `CHORD_CONTRACTION` per step (near a jamming
    point they shrink by orders of magnitude); only a slower step factorises again, at the
    current point. The self-stress of the certificate is solved with the same factors,
    refined iteratively against the Jacobian at the solution.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Current positions (any units; the mean diameter is a good unit).
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    i, j : ndarray, shape (M,), int
        The contacts, between stable particles.
    stable : ndarray, shape (N,), bool
        Non-rattlers; every stable particle has a contact.
    factors : Factors, optional
        Factors of a matrix close to the Jacobian at `positions` (the same unknowns), used
        for the first chord steps instead of a new factorisation.
    wall_particle, wall : ndarray, shape (K,), int, optional
        Contacts of stable particles with the container's walls (`calippso.geometry.walls`
        numbering); none by default.
    boundaries : Boundaries, optional
        The container (`calippso.geometry.boundaries`); None: periodic along every axis. Its zero
        modes are removed by `pinned_coordinates`. The network is square when M + K =
        (free coordinates) + 1.

    Returns
    -------
    Refinement or None
        None when the network is not square, the Jacobian is singular or Newton does not
        converge. The caller certifies the rest: `Refinement.positive`, and no overlap of
        pairs (or crossing of walls) that are not contacts.
    """
    n, d = positions.shape
    wall_particle = np.zeros(0, np.int64) if wall_particle is None else wall_particle
    wall = np.zeros(0, np.int64) if wall is None else wall
    periodic, cylinder_axes, pinned = None, (), None
    if boundaries is not None and not boundaries.is_periodic:
        periodic, cylinder_axes = boundaries.periodic, boundaries.cylinder_axes
        pinned = pinned_coordinates(positions, box, stable, boundaries)
    columns = free_columns(stable, d, pinned)
    free = columns >= 0
    n_unknowns = int(np.count_nonzero(free)) + 1
    m = i.shape[0]
    if np.count_nonzero(stable) < 2 or m + wall_particle.shape[0] != n_unknowns:
        return None
    i_cols = np.concatenate([columns[i], columns[wall_particle]])
    j_cols = np.concatenate([columns[j], np.full((wall.shape[0], d), -1, dtype=np.int64)])
    sigma = np.concatenate([0.5 * (diameters[i] + diameters[j]), 0.5 * diameters[wall_particle]])
    inverse_sigma2 = 1.0 / sigma**2
    start_vectors = minimum_image(positions[i] - positions[j], box, periodic)
    image_shift = start_vectors - (positions[i] - positions[j])
    moved = positions.copy()

    def contact_vectors() -> np.ndarray:
        return np.concatenate([moved[i] - moved[j] + image_shift, wall_rows_of(
            moved, diameters, box, wall_particle, wall, cylinder_axes).vectors])

    vectors = contact_vectors()
    gamma = float(np.mean(np.einsum("md,md->m", vectors, vectors) * inverse_sigma2))

    def residual_and_vectors() -> tuple[np.ndarray, np.ndarray]:
        vectors = contact_vectors()
        return np.einsum("md,md->m", vectors, vectors) * inverse_sigma2 - gamma, vectors

    def jacobian(vectors: np.ndarray) -> sp.csc_matrix:
        return contact_equations_jacobian(vectors, inverse_sigma2, i_cols, j_cols, n_unknowns)

    residual, vectors = residual_and_vectors()
    factorizations, previous, made = 0, np.inf, None
    if factors is None:
        matrix = jacobian(vectors)
        factors = factorize(matrix, strict=False)
        if factors is None:
            return None
        factorizations, made = 1, (factors, matrix)
    for iteration in range(1, MAX_ITERATIONS + 1):
        correction = factors.solve(-residual)
        largest = float(np.abs(correction[:-1]).max(initial=0.0))
        if not (np.all(np.isfinite(correction)) and largest <= MAX_CORRECTION):
            if made is not None:
                return None
            # the given factors are too far from this Jacobian: factorise it
            matrix = jacobian(vectors)
            factors = factorize(matrix, strict=False)
            if factors is None:
                return None
            factorizations, made, previous = factorizations + 1, (factors, matrix), np.inf
            continue
        moved[free] += correction[:-1]
        gamma += float(correction[-1])
        residual, vectors = residual_and_vectors()
        if largest < STEP_TOLERANCE:
            break
        stalled = largest > CHORD_CONTRACTION * previous
        if stalled and float(np.abs(residual).max()) <= ROUNDOFF_RESIDUAL:
            break   # the corrections are round-off of a large system: converged
        if stalled:   # the chord is too slow: a Newton step
            matrix = jacobian(vectors)
            factors = factorize(matrix, strict=False)
            if factors is None:
                return None
            factorizations, made = factorizations + 1, (factors, matrix)
            largest = np.inf
        previous = largest
    else:
        return None
    worst = float(np.abs(residual).max())
    if worst > RESIDUAL_TOLERANCE or gamma <= 0:
        return None
    stress = self_stress(factors, jacobian(vectors))  # J_xᵀ y = 0 (balance), Σ y = 1
    if stress is None:
        return None
    new_sigma = sigma * np.sqrt(gamma)
    distances = np.sqrt(np.einsum("md,md->m", vectors, vectors))
    forces = distances * stress / new_sigma**2  # f = μ/2 with μ = 2|r| y / σ'²
    return Refinement(
        positions=wrap(moved, box, periodic), diameters=diameters * np.sqrt(gamma),
        forces=forces[:m], iterations=iteration, factorizations=factorizations,
        sqrt_gamma_minus_1=float(np.sqrt(gamma) - 1.0),
        max_displacement=float(np.abs(moved[free] - positions[free]).max(initial=0.0)),
        residual=worst, factorization=made, wall_forces=forces[m:])


def self_stress(factors: Factors, jacobian: sp.csc_matrix) -> np.ndarray | None:
    """The solution y of Jᵀ y = (0, …, 0, −1), from factors of a nearby Jacobian.

    Iterative refinement: y ← y + F⁻ᵀ (b − Jᵀ y) with F the given factors, until every
    row of the residual is below `REFINEMENT_TOLERANCE` × that row of |Jᵀ| |y| + |b| (a
    componentwise backward error of a few units of round-off, as a factorisation of J
    itself would give: each particle balanced to round-off of its own forces). When that
    takes more than `MAX_REFINEMENTS` steps, J itself is factorised (PARDISO factors with
    perturbed pivots are refined the same way). None when J is singular.
    """
    target = np.zeros(jacobian.shape[0])
    target[-1] = -1.0
    transposed = jacobian.T.tocsr()
    stress = _refined_transposed_solve(factors, transposed, target)
    if stress is not None:
        return stress
    exact = factorize(jacobian)
    if exact is not None:
        stress = exact.solve(target, trans="T")
        return stress if np.all(np.isfinite(stress)) else None
    perturbed = factorize(jacobian, strict=False)
    return None if perturbed is None else _refined_transposed_solve(perturbed, transposed,
                                                                     target)


def _refined_transposed_solve(factors: Factors, transposed: sp.csr_matrix,
                              target: np.ndarray) -> np.ndarray | None:
    """y with Jᵀ y = target by iterative refinement with `factors` (`self_stress`), or None
    when `MAX_REFINEMENTS` steps do not reach the backward error."""
    magnitudes = abs(transposed)
    stress = factors.solve(target, trans="T")
    for _ in range(MAX_REFINEMENTS + 1):
        if not np.all(np.isfinite(stress)):
            return None
        remainder = target - transposed @ stress
        scale = magnitudes @ np.abs(stress) + np.abs(target)   # row by row: force units
        if np.all(np.abs(remainder) <= REFINEMENT_TOLERANCE * scale):
            return stress
        stress = stress + factors.solve(remainder, trans="T")
    return None
