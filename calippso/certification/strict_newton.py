"""The strictly jammed point of a contact network, by Newton's method in a deformable box.

The deformable box's LP (`calippso.deformable`) reads a contact network from its duals. When
that network has the strict count, N_c = d (N_s − 1) + d(d+1)/2 (docs/theory.md, A deformable
box in the LP), its jamming point solves the square system

    |F r_c + u_i − u_j|² / σ_c² = Γ      for every contact c = (i, j),

in the displacements u of the stable particles (one pinned), the d(d+1)/2 − 1 entries of a
symmetric, traceless strain ε of the box (F = I + ε; the trace is held at zero, which fixes
the scale that the equations leave free: F → c F, Γ → c² Γ is a solution too) and the
common inflation Γ of the squared diameters. Every Newton correction is applied to the
configuration (centres x → F x + u, box vectors H → F H), and the next one is linearised
there, so that the Jacobian always has the LP's own rows: 2 r/σ² on u_i, −2 r/σ² on u_j,
2 rᵀ ε r/σ² on the strain, −1 on Γ.

The answer is certified as the fixed box's Newton stage certifies it (`calippso.certification.newton`):
the self-stress y solving Jᵀ y = (0, …, 0, −1) gives the LP's multipliers at the new point.
Its rows on u say that the forces balance on every stable particle, its rows on the strain
that their stress is isotropic, and y > 0 on every contact makes them dual feasible: with
no other pair overlapping, the deformable LP there has the optimum u = 0, ε = 0, Γ = 1. A
non-singular Jacobian leaves no floppy mode of the strict rows, so the packing is strictly
jammed. `clear_rattlers` moves the rattlers that the strict point's small move overlaps.

In a container the strain acts on the periodic axes alone (traceless on them: the volume
row binds at a jamming point) and a contact of particle i with a wall adds the equation
δ_w²/σ_w² = Γ of the fixed box (`calippso.certification.newton`), whose strain terms are zero
(a wall's distance does not depend on the periodic axes); the container's zero modes are
pinned (`calippso.certification.newton.pinned_coordinates`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .newton import (CHORD_CONTRACTION, MAX_CORRECTION, MAX_ITERATIONS, MIN_FORCE_RATIO,
                     RESIDUAL_TOLERANCE, ROUNDOFF_RESIDUAL, STEP_TOLERANCE,
                     contact_equations_jacobian, free_columns, pinned_coordinates, self_stress)
from ..deformable import strain_coefficients, strain_matrix
from ..geometry.boundaries import Boundaries
from ..geometry.periodic import lattice_wrap
from ..geometry.walls import wall_rows_of
from ..geometry.sheared_search import sheared_pairs_within
from .sparse_lu import factorize

__all__ = ["StrictRefinement", "refine_strict", "strict_unknowns", "clear_rattlers",
           "NEAR_CONTACT"]

#: Passes that move rattlers out of overlaps after the strict Newton stage, and the gap
#: (relative to the pair's contact distance) that each pass leaves.
RATTLER_PASSES = 16
RATTLER_CLEARANCE = 1e-12
#: The search for pairs that touch reaches this fraction beyond the largest diameter.
NEAR_CONTACT = 1e-6


@dataclass(frozen=True, eq=False)
class StrictRefinement:
    """The strictly jammed point of a network (`refine_strict`).

    Attributes
    ----------
    positions : ndarray, shape (N, d)
        Centres wrapped into the new box (rattlers moved with the strain only).
    matrix : ndarray, shape (d, d)
        The new box vectors as columns, F H.
    diameters : ndarray, shape (N,)
        Diameters times √Γ.
    forces : ndarray, shape (M,)
        Contact forces in the order of the contacts given, in the LP's normalisation
        (f = μ/2 with Σ μ_c σ_c²/(2|r_c|) = 1).
    wall_forces : ndarray, shape (K,)
        Forces of the wall contacts, in the order given, in the units of `forces`.
    iterations : int
        Corrections applied.
    factorizations : int
        Sparse LU factorisations of the Jacobian.
    sqrt_gamma_minus_1 : float
        √Γ − 1: the diameter growth from the start.
    max_displacement : float
        Largest displacement of a stable particle from the start, strain included (length
        units of the input).
    residual : float
        max_c | |r_c|²/σ_c² − Γ | at the end.
    """

    positions: np.ndarray
    matrix: np.ndarray
    diameters: np.ndarray
    forces: np.ndarray
    iterations: int
    factorizations: int
    sqrt_gamma_minus_1: float
    max_displacement: float
    residual: float
    wall_forces: np.ndarray

    @property
    def positive(self) -> bool:
        """Every force (walls included) is positive, above
        `calippso.certification.newton.MIN_FORCE_RATIO` × the largest."""
        every = np.concatenate([self.forces, self.wall_forces])
        return bool(every.size == 0 or every.min() > MIN_FORCE_RATIO * every.max())


def strict_unknowns(n_free: int, n_periodic: int) -> int:
    """Unknowns of the strict contact equations: the `n_free` displacement coordinates
    (d (N_s − 1) in a periodic box), the d_p(d_p+1)/2 − 1 entries of a traceless symmetric
    strain of the `n_periodic` = d_p periodic axes, and Γ."""
    return n_free + n_periodic * (n_periodic + 1) // 2


def _strain_terms(vectors: np.ndarray, periodic: np.ndarray) -> np.ndarray:
    """rᵀ ε r for the traceless strain variables of the `periodic` axes (those of
    `calippso.deformable.strain_matrix` but the trace, held at zero), shape
    (M, d_p(d_p+1)/2 − 1); a wall row's vector (zero on the periodic axes) has none."""
    return strain_coefficients(vectors, np.ones(vectors.shape[0]), periodic)[:, :-1]


def _strain_of(variables: np.ndarray, periodic: np.ndarray) -> np.ndarray:
    """The traceless symmetric strain of the `periodic` axes, shape (d, d), from its
    variables (`_strain_terms`); zero in the rows and columns of the other axes."""
    return strain_matrix(np.append(variables, 0.0), periodic)


def _jacobian(vectors: np.ndarray, inverse_sigma2: np.ndarray, i_cols: np.ndarray,
              j_cols: np.ndarray, n_moves: int, periodic: np.ndarray) -> sp.csc_matrix:
    """Jacobian of |r_c|²/σ_c² − Γ at the current configuration (module docstring), shape
    (M, n_moves + d_p(d_p+1)/2): the fixed box's columns (`calippso.certification.newton`;
    `i_cols`, `j_cols` (M, d) hold the displacement columns, −1 for a pinned coordinate or
    a wall) with the strain's 2 rᵀ ε r/σ² of the `periodic` axes between the
    displacements and Γ."""
    m = vectors.shape[0]
    strain = 2.0 * _strain_terms(vectors, periodic) * inverse_sigma2[:, None]
    k = strain.shape[1]
    fixed_box = contact_equations_jacobian(vectors, inverse_sigma2, i_cols, j_cols,
                                           n_moves + k + 1)
    strain_block = sp.csc_matrix(
        (strain.ravel(), (np.repeat(np.arange(m), k), np.tile(n_moves + np.arange(k), m))),
        shape=fixed_box.shape)
    return (fixed_box + strain_block).tocsc()


def refine_strict(positions: np.ndarray, diameters: np.ndarray, matrix: np.ndarray,
                  i: np.ndarray, j: np.ndarray, vectors: np.ndarray, stable: np.ndarray, *,
                  wall_particle: np.ndarray | None = None, wall: np.ndarray | None = None,
                  boundaries: Boundaries | None = None) -> StrictRefinement | None:
    """Solve the strict contact equations of a network and compute its forces.

    Chord steps: the Jacobian is factorised at the start and reused while the corrections
    shrink by `calippso.certification.newton.CHORD_CONTRACTION` per step, factorised again otherwise (the
    fixed box's `calippso.certification.newton.refine_isostatic` does the same).

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (any units; the mean diameter is a good one).
    diameters : ndarray, shape (N,)
    matrix : ndarray, shape (d, d)
        Box vectors as columns; in a container, its search cell
        (`calippso.geometry.boundaries.Boundaries.search_cell`).
    i, j : ndarray, shape (M,), int
        The contacts, between stable particles.
    vectors : ndarray, shape (M, d)
        Their separations r_c = x_i − x_j (minimum image) at `positions`.
    stable : ndarray, shape (N,), bool
        Non-rattlers; the container's zero modes are pinned (the first one, in a periodic
        box).
    wall_particle, wall : ndarray, shape (K,), int, optional
        Contacts of stable particles with the container's walls (`calippso.geometry.walls`
        numbering); none by default.
    boundaries : Boundaries, optional
        The container; None: periodic along every axis.

    Returns
    -------
    StrictRefinement or None
        None when the network does not have the strict count, the Jacobian is singular or
        Newton does not converge. The caller certifies the rest: `StrictRefinement.positive`
        and no overlap of other pairs (or crossing of walls).
    """
    n, d = positions.shape
    boundaries = Boundaries.all_periodic(d) if boundaries is None else boundaries
    periodic = boundaries.periodic
    wall_particle = np.zeros(0, np.int64) if wall_particle is None else wall_particle
    wall = np.zeros(0, np.int64) if wall is None else wall
    sides = np.diag(boundaries.box_cell(matrix))
    columns = free_columns(stable, d, pinned_coordinates(positions, sides, stable, boundaries))
    free = columns >= 0
    n_moves = int(np.count_nonzero(free))
    m = i.shape[0]
    if (np.count_nonzero(stable) < 2
            or m + wall_particle.shape[0] != strict_unknowns(n_moves, boundaries.n_periodic)):
        return None
    i_cols = np.concatenate([columns[i], columns[wall_particle]])
    j_cols = np.concatenate([columns[j], np.full((wall.shape[0], d), -1, dtype=np.int64)])
    sigma = np.concatenate([0.5 * (diameters[i] + diameters[j]), 0.5 * diameters[wall_particle]])
    inverse_sigma2 = 1.0 / sigma**2
    moved, box = positions.copy(), matrix.copy()
    image_shift = vectors - (positions[i] - positions[j])

    def contact_vectors() -> np.ndarray:
        return np.concatenate([moved[i] - moved[j] + image_shift, wall_rows_of(
            moved, diameters, sides, wall_particle, wall, boundaries.cylinder_axes).vectors])

    vectors = contact_vectors()
    gamma = float(np.mean(np.einsum("md,md->m", vectors, vectors) * inverse_sigma2))

    def residual_of(current: np.ndarray) -> np.ndarray:
        return np.einsum("md,md->m", current, current) * inverse_sigma2 - gamma

    def factors_at(current: np.ndarray):
        jacobian = _jacobian(current, inverse_sigma2, i_cols, j_cols, n_moves, periodic)
        return factorize(jacobian, strict=False), jacobian

    factors, jacobian = factors_at(vectors)
    if factors is None:
        return None
    factorizations, previous = 1, np.inf
    residual = residual_of(vectors)
    for iteration in range(1, MAX_ITERATIONS + 1):
        correction = factors.solve(-residual)
        displacement = np.zeros((n, d))
        displacement[free] = correction[:n_moves]
        deformation = np.eye(d) + _strain_of(correction[n_moves:-1], periodic)
        largest = float(np.abs(correction[:-1]).max(initial=0.0))
        if not (np.all(np.isfinite(correction)) and largest <= MAX_CORRECTION):
            return None
        moved = moved @ deformation.T + displacement
        box = deformation @ box
        image_shift = image_shift @ deformation.T
        gamma += float(correction[-1])
        vectors = contact_vectors()
        residual = residual_of(vectors)
        if largest < STEP_TOLERANCE:
            break
        stalled = largest > CHORD_CONTRACTION * previous
        if stalled and float(np.abs(residual).max()) <= ROUNDOFF_RESIDUAL:
            break
        if stalled:
            factors, jacobian = factors_at(vectors)
            if factors is None:
                return None
            factorizations, largest = factorizations + 1, np.inf
        previous = largest
    else:
        return None
    worst = float(np.abs(residual).max())
    if worst > RESIDUAL_TOLERANCE or gamma <= 0:
        return None
    stress = self_stress(factors, _jacobian(vectors, inverse_sigma2, i_cols, j_cols, n_moves,
                                            periodic))
    if stress is None:
        return None
    distances = np.sqrt(np.einsum("md,md->m", vectors, vectors))
    forces = distances * stress / (sigma**2 * gamma)
    # the stable particles' largest move, the box's strain included (rattlers move with it)
    travel = float(np.abs(moved[stable] - positions[stable]).max(initial=0.0))
    return StrictRefinement(
        positions=lattice_wrap(moved, box), matrix=box, diameters=diameters * np.sqrt(gamma),
        forces=forces[:m], iterations=iteration, factorizations=factorizations,
        sqrt_gamma_minus_1=float(np.sqrt(gamma) - 1.0), max_displacement=travel,
        residual=worst, wall_forces=forces[m:])


def clear_rattlers(positions: np.ndarray, diameters: np.ndarray, matrix: np.ndarray,
                   keys: np.ndarray, rattlers: np.ndarray, round_off: float
                   ) -> tuple[np.ndarray | None, bool]:
    """The positions with every rattler that a pair overlaps beyond `round_off` moved out
    of it along the pair's normal (a rattler that touched its cage after the last LP is
    overlapped by the cage's small move to the strict point).

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres at the strict point, in the cell of `matrix`.
    diameters : ndarray, shape (N,)
    matrix : ndarray, shape (d, d)
        Box vectors as columns.
    keys : ndarray, shape (M,), int
        The contacts' keys min(i, j) N + max(i, j).
    rattlers : ndarray, shape (N,), bool
    round_off : float
        Relative overlap tolerated (the LPs' feasibility round-off).

    Returns
    -------
    (ndarray or None, bool)
        The moved positions; None when a rattler is still overlapped after
        `RATTLER_PASSES` passes, or when two stable particles that are no contact overlap
        beyond `round_off` (then the flag is True).
    """
    n = positions.shape[0]
    cutoff = float(diameters.max()) * (1.0 + NEAR_CONTACT)
    for _ in range(RATTLER_PASSES + 1):
        close = sheared_pairs_within(positions, diameters, matrix, cutoff)
        outside = ~np.isin(np.minimum(close.i, close.j) * n + np.maximum(close.i, close.j),
                           keys)
        caged = rattlers[close.i] | rattlers[close.j]
        if np.any(outside & ~caged & (close.gaps < -round_off)):
            return None, True
        overlapping = outside & caged & (close.gaps < -round_off)
        if not overlapping.any():
            return positions, False
        i, j = close.i[overlapping], close.j[overlapping]
        # each overlap pushes its rattler(s) out to a gap of RATTLER_CLEARANCE (halves for
        # two); a rattler moves by the mean of its pushes (their sum overshoots in a cage
        # that it fits tightly)
        depth = (close.sigma * (1.0 + RATTLER_CLEARANCE) - close.distances)[overlapping]
        normals = close.vectors[overlapping] / close.distances[overlapping, None]
        share = 1.0 / (rattlers[i].astype(float) + rattlers[j].astype(float))
        move = np.zeros_like(positions)
        pushes = np.zeros(positions.shape[0])
        for ends, sign in ((i, 1.0), (j, -1.0)):
            mask = rattlers[ends]
            np.add.at(move, ends[mask], sign * (share * depth)[mask, None] * normals[mask])
            np.add.at(pushes, ends[mask], 1.0)
        positions = lattice_wrap(positions + move / np.maximum(pushes, 1.0)[:, None], matrix)
    return None, False
