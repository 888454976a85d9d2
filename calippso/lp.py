"""The linearised CALiPPSO problem as sparse data, and the safe choice of its rows.

For positions r, diameters σ and a bound b on every displacement component, the LP is

    maximise γ over (s_1 … s_N ∈ R^d, γ)
    subject to  n_ij·(s_i − s_j) − γ σ_ij²/(2|r_ij|) ≥ −(|r_ij| − σ_ij)(|r_ij| + σ_ij)/(2|r_ij|)
                −b ≤ s_iμ ≤ b, s_pinned = 0, γ ≥ −1,

which is |r_ij|² + 2 r_ij·(s_i − s_j) ≥ Γ σ_ij² with Γ = 1 + γ, divided by 2|r_ij| so that
every row is in length units and its dual μ_ij is twice the contact force (f_ij = μ_ij/2).
Writing the right-hand side as a product of the gap and γ = Γ − 1 keeps digits near contact.

Which rows are kept. Any pair p bounds the LP optimum: Γ σ_p² ≤ |r_p|² + 2|r_p||s_p| ≤
(|r_p| + 2√d b)², so √Γ ≤ g := min_p (|r_p| + 2√d b)/σ_p. A pair left out with
|r_ij| − 2√d b > g σ_ij can then never come into contact during the step, in exact arithmetic.
Only pairs within g σ_ij + 2√d b are kept; the loop still checks every pair after each update.

Container walls (`calippso.geometry.walls`) add one row per particle within g σ_i/2 + b of a flat
wall (the displacement towards it is one component, at most b) or g σ_i/2 + √2 b of a
cylinder, of the same form with the wall as a partner that does not move; a cylinder's row
uses the distance δ − b²/ρ, which its curvature cannot undercut over the step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .geometry.neighbors import NeighborSearch, Pairs
from .geometry.walls import EMPTY_WALLS, WallRows, empty_walls, wall_rows_within

__all__ = ["LinearProgram", "select_pairs", "select_walls", "build_lp", "cylinder_step_limit"]


@dataclass(frozen=True, eq=False)
class LinearProgram:
    """maximise x[-1] subject to matrix @ x ≥ row_lower and col_lower ≤ x ≤ col_upper.

    Attributes
    ----------
    matrix : scipy.sparse.csc_matrix, shape (M + K, N d + 1)
        One row per kept pair, then one per kept particle–wall pair; columns are s_iμ at
        i d + μ, then γ.
    row_lower : ndarray, shape (M,)
    col_lower, col_upper : ndarray, shape (N d + 1,)
    pairs : Pairs
        The pair behind every row, in row order.
    n : int
        Number of particles.
    d : int
        Dimension.
    step_bound : float
        Bound on each displacement component (mean diameters).
    walls : WallRows
        The particle–wall pair behind every row after the pairs', in row order.
    zero_modes : int
        Rigid motions the container leaves free (d in a periodic box): the isostatic count
        is d N_s + 1 − zero_modes.
    """

    matrix: sp.csc_matrix
    row_lower: np.ndarray
    col_lower: np.ndarray
    col_upper: np.ndarray
    pairs: Pairs
    n: int
    d: int
    step_bound: float
    walls: WallRows
    zero_modes: int

    @property
    def n_rows(self) -> int:
        """Number of constraints M + K."""
        return self.matrix.shape[0]

    @property
    def n_cols(self) -> int:
        """Number of variables N d + 1."""
        return self.matrix.shape[1]

    @property
    def gamma_coefficients(self) -> np.ndarray:
        """σ_ij²/(2|r_ij|) for every row (σ_w²/(2δ') for a wall row,
        `calippso.geometry.walls.WallRows.row_distances`): the (negated)
        coefficient of γ, shape (M + K,)."""
        coefficients = self.pairs.sigma**2 / (2.0 * self.pairs.distances)
        if not len(self.walls):
            return coefficients
        return np.concatenate([coefficients, self.walls.sigma**2
                               / (2.0 * self.walls.row_distances(self.step_bound))])


def growth_bound(search: NeighborSearch, step_bound: float) -> float:
    """Upper bound g on √Γ for this step, from every particle's nearest neighbour (see module doc)."""
    distances, neighbours = search.nearest_neighbours()
    sigma = 0.5 * (search.diameters + search.diameters[neighbours])
    reach = 2.0 * np.sqrt(search.d) * step_bound
    return float(np.min((distances + reach) / sigma))


def select_pairs(search: NeighborSearch, step_bound: float) -> Pairs:
    """Every pair that could come into contact within a step bounded by `step_bound`.

    Parameters
    ----------
    search : NeighborSearch
        Current positions and diameters (mean diameter 1).
    step_bound : float
        Bound on each displacement component.

    Raises
    ------
    ValueError
        If the pairs needed would reach beyond half the box (call with a smaller bound).
    """
    reach = 2.0 * np.sqrt(search.d) * step_bound
    g = growth_bound(search, step_bound)
    cutoff = g * float(search.diameters.max()) + reach
    pairs = search.pairs_within(cutoff)
    return pairs.subset(pairs.distances <= g * pairs.sigma + reach)


def select_walls(search: NeighborSearch, step_bound: float, boundaries) -> WallRows:
    """Every particle–wall pair that could come into contact within a step bounded by
    `step_bound`: δ ≤ g σ_i/2 + b (√2 b for a cylinder), with g the bound on √Γ of
    `growth_bound`.

    Parameters
    ----------
    search : NeighborSearch
        Current positions and diameters (mean diameter 1).
    step_bound : float
        Bound b on each displacement component.
    boundaries : calippso.geometry.boundaries.Boundaries
        The container.
    """
    if boundaries.is_periodic:
        return empty_walls(search.d)
    return wall_rows_within(search.positions, search.diameters, search.box, boundaries,
                            step_bound, growth_bound(search, step_bound))


def largest_safe_step(search: NeighborSearch, step_bound: float, boundaries=None) -> float:
    """The largest bound ≤ `step_bound` whose row selection stays below half the smallest
    periodic box side, and (in a cylinder) whose curvature margin b²/ρ leaves every
    particle near the wall at least half its distance δ (`calippso.geometry.walls`).

    Returns 0.0 when even a vanishing step would need pairs beyond half the box.
    """
    if boundaries is not None:
        step_bound = min(step_bound, cylinder_step_limit(search.positions, search.diameters,
                                                         search.box, boundaries))
    half = search.half_period
    root_d = np.sqrt(search.d)
    for _ in range(60):
        g = growth_bound(search, step_bound)
        if g * float(search.diameters.max()) + 2.0 * root_d * step_bound < half * (1 - 1e-12):
            return step_bound
        step_bound *= 0.5
    return 0.0


def cylinder_step_limit(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                        boundaries) -> float:
    """The largest b with b²/ρ ≤ δ/2 for every particle within a diameter of the cylinder
    (+inf when none is, or without a cylinder): its LP row then keeps a positive distance
    δ − b²/ρ. Shapes: positions (N, d), diameters (N,), box (d,) the sides."""
    if not boundaries.cylinder_axes:
        return float("inf")
    near = wall_rows_within(positions, diameters, box, boundaries, 0.0, 2.0)
    near = near.subset(near.curvature > 0)
    if not len(near):
        return float("inf")
    return float(np.sqrt(0.5 * np.min(near.distances / near.curvature)))


def build_lp(pairs: Pairs, n: int, d: int, step_bound: float, fixed: np.ndarray,
             walls: WallRows = EMPTY_WALLS, zero_modes: int | None = None) -> LinearProgram:
    """Assemble the sparse LP for the given rows.

    Parameters
    ----------
    pairs : Pairs
        Rows to keep (from `select_pairs`), in mean-diameter units.
    n, d : int
        Particles and dimension.
    step_bound : float
        Bound b on every displacement component.
    fixed : ndarray, shape (N,) or (N, d), bool
        Particles (or displacement components) fixed to zero: the pin, along the periodic
        axes only in a box with walls; rattlers in a clean-up LP.
    walls : WallRows
        Particle–wall rows to keep (from `select_walls`), after the pairs'.
    zero_modes : int, optional
        Rigid motions the container leaves free; None: d (a periodic box).
    """
    m = len(pairs)
    normals = pairs.vectors / pairs.distances[:, None]
    coordinate = np.arange(d)
    columns = np.concatenate(
        [pairs.i[:, None] * d + coordinate, pairs.j[:, None] * d + coordinate,
         np.full((m, 1), n * d)], axis=1)
    gamma_coefficient = pairs.sigma**2 / (2.0 * pairs.distances)
    values = np.concatenate([normals, -normals, -gamma_coefficient[:, None]], axis=1)
    rows = np.repeat(np.arange(m), 2 * d + 1)
    row_lower = -(pairs.distances - pairs.sigma) * (pairs.distances + pairs.sigma) / (
        2.0 * pairs.distances)
    values, rows, columns = values.ravel(), rows, columns.ravel()
    if len(walls):
        k = len(walls)
        distances = walls.row_distances(step_bound)
        row, axis = np.nonzero(walls.normals)   # one entry per normal component
        values = np.concatenate([values, walls.normals[row, axis],
                                 -walls.sigma**2 / (2.0 * distances)])
        rows = np.concatenate([rows, m + row, m + np.arange(k)])
        columns = np.concatenate([columns, walls.particle[row] * d + axis,
                                  np.full(k, n * d)])
        row_lower = np.concatenate([row_lower, -(distances - walls.sigma) * (
            distances + walls.sigma) / (2.0 * distances)])
    matrix = sp.csc_matrix((values, (rows, columns)), shape=(m + len(walls), n * d + 1))
    col_lower = np.full(n * d + 1, -step_bound)
    col_upper = np.full(n * d + 1, step_bound)
    fixed_columns = np.flatnonzero(np.broadcast_to(fixed.reshape(n, -1), (n, d)))
    col_lower[fixed_columns] = 0.0
    col_upper[fixed_columns] = 0.0
    col_lower[-1], col_upper[-1] = -1.0, np.inf
    return LinearProgram(matrix, row_lower, col_lower, col_upper, pairs, n, d, step_bound,
                         walls, d if zero_modes is None else zero_modes)
