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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .neighbors import NeighborSearch, Pairs

__all__ = ["LinearProgram", "select_pairs", "build_lp"]


@dataclass(frozen=True, eq=False)
class LinearProgram:
    """maximise x[-1] subject to matrix @ x ≥ row_lower and col_lower ≤ x ≤ col_upper.

    Attributes
    ----------
    matrix : scipy.sparse.csc_matrix, shape (M, N d + 1)
        One row per kept pair; columns are s_iμ at i d + μ, then γ.
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
    """

    matrix: sp.csc_matrix
    row_lower: np.ndarray
    col_lower: np.ndarray
    col_upper: np.ndarray
    pairs: Pairs
    n: int
    d: int
    step_bound: float

    @property
    def n_rows(self) -> int:
        """Number of pair constraints M."""
        return self.matrix.shape[0]

    @property
    def n_cols(self) -> int:
        """Number of variables N d + 1."""
        return self.matrix.shape[1]

    @property
    def gamma_coefficients(self) -> np.ndarray:
        """σ_ij²/(2|r_ij|) for every row: the (negated) coefficient of γ, shape (M,)."""
        return self.pairs.sigma**2 / (2.0 * self.pairs.distances)


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


def largest_safe_step(search: NeighborSearch, step_bound: float) -> float:
    """The largest bound ≤ `step_bound` whose row selection stays below half the smallest box side.

    Returns 0.0 when even a vanishing step would need pairs beyond half the box.
    """
    half = 0.5 * float(search.box.min())
    root_d = np.sqrt(search.d)
    for _ in range(60):
        g = growth_bound(search, step_bound)
        if g * float(search.diameters.max()) + 2.0 * root_d * step_bound < half * (1 - 1e-12):
            return step_bound
        step_bound *= 0.5
    return 0.0


def build_lp(pairs: Pairs, n: int, d: int, step_bound: float, fixed: np.ndarray) -> LinearProgram:
    """Assemble the sparse LP for the given rows.

    Parameters
    ----------
    pairs : Pairs
        Rows to keep (from `select_pairs`), in mean-diameter units.
    n, d : int
        Particles and dimension.
    step_bound : float
        Bound b on every displacement component.
    fixed : ndarray, shape (N,), bool
        Particles whose displacement is fixed to zero (the pin; rattlers in a clean-up LP).
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
    matrix = sp.csc_matrix((values.ravel(), (rows, columns.ravel())), shape=(m, n * d + 1))
    row_lower = -(pairs.distances - pairs.sigma) * (pairs.distances + pairs.sigma) / (
        2.0 * pairs.distances)
    col_lower = np.full(n * d + 1, -step_bound)
    col_upper = np.full(n * d + 1, step_bound)
    fixed_columns = (np.flatnonzero(fixed)[:, None] * d + coordinate).ravel()
    col_lower[fixed_columns] = 0.0
    col_upper[fixed_columns] = 0.0
    col_lower[-1], col_upper[-1] = -1.0, np.inf
    return LinearProgram(matrix, row_lower, col_lower, col_upper, pairs, n, d, step_bound)
