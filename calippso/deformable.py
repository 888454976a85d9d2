"""The deformable box: the box's strain as columns of the loop's LP, towards strict jamming.

`jam(packing, box="deformable")` runs the CALiPPSO loop (`calippso.ilp`) with, in every LP,
besides γ = Γ − 1, a symmetric strain ε of the box (d(d+1)/2 variables) and the displacements
s'_i of the centres, their affine part included: the box vectors become (I + ε) H and the
centres r_i + s'_i. A pair's separation is r_ij = r_i − r_j + m_ij, with m_ij a lattice vector
(zero unless the pair's minimum image crosses the boundary), and it becomes
r_ij + s'_i − s'_j + ε m_ij exactly. Its linearised non-overlap condition is that of the
fixed box with the strain's share added,

    n_ij·(s'_i − s'_j) + n_ijᵀ ε m_ij − γ σ_ij²/(2|r_ij|) ≥ −(|r_ij|² − σ_ij²)/(2|r_ij|),

and the box's volume may not grow, tr ε ≤ 0. The LP maximises γ: at a volume that does not
grow, that is the growth of the packing fraction (Donev, Torquato, Stillinger & Connelly,
J. Comput. Phys. 197, 139 (2004); Torquato & Jiao, Phys. Rev. E 82, 061302 (2010)). This
is the affine form (centres (I + ε) r_i + s_i) with s'_i = s_i + ε r_i; written so, the strain
columns hold entries on the rows of the pairs across the boundary only (about a sixth of the
rows at N = 1024 in d = 3), and an LP costs about as much as the fixed box's.

The strain variables are the diagonal differences ε_μμ (μ < d), the off-diagonal entries
ε_μν (μ < ν) and the trace t = tr ε, with ε_dd = t − Σ_{μ<d} ε_μμ; the volume condition is
then the column bound t ≤ 0 and the LP keeps one row per pair, so that the basis of one LP
warm-starts the next. Each s'_iμ is bounded by the step bound b, every strain variable by
e = `STRAIN_BOUND` b / W (W the longest box vector), and the centres are taken in the cell
centred on the pinned particle, so that the affine part fits the bound; a pair then moves by
at most 2√d b + √(2d² − 1) e |m_ij| in a step (`select_rows`).

At the optimum, the strain columns say that the contact stress Σ μ_ij r_ij r_ijᵀ/|r_ij| is
p I, with p the multiplier of t ≤ 0: the stress is isotropic and the pressure is the
volume's multiplier (`JammingResult.stress`, docs/theory.md).

In a container (flat walls on some axes, or a cylinder) the walls stay where they are: the
strain acts on the periodic axes alone (d_p(d_p+1)/2 variables for d_p periodic axes, the
trace being that of the periodic block), the box matrix keeps its bounded axes apart
(`calippso.geometry.boundaries.Boundaries.check_block_matrix`), and the wall rows are the
fixed box's (`calippso.lp`): the affine part ε r_i of s'_i moves a centre along the periodic
axes only, and a wall's distance does not depend on them. The loop holds the box matrix
padded along the bounded axes (`Boundaries.search_cell`), so that its lattice searches
find no image across a wall. A container without a periodic axis has no strain and is
refused.

This module holds what is the box's: the strain variables and their columns
(`strained_lp`), the rows of a step in a sheared cell (`select_rows`), and the strain's share
of an LP's answer (`analyse_strained`). The loop's stages run it: the LP step
(`calippso.stages.lp_step`), the strict Newton stage
(`calippso.stages.strict_newton_stage`) and the finish (`calippso.stages.strict_finish`).
The finish reads the contact stress (`calippso.geometry.contacts.contact_stress`), the strain
certificate of the last LP and the strict certificate
(`calippso.certification.strict_certificate`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from .geometry.boundaries import Boundaries
from .geometry.sheared_search import half_shortest_vector, sheared_pairs_within
from .geometry.walls import WallRows, empty_walls, wall_rows_within
from .lp import LinearProgram, build_lp
from .geometry.neighbors import Pairs
from .settings import JamSettings
from .solvers import LPSolution
from .step import BINDING_REDUCED_COST, Step, analyse, at_bound

__all__ = ["strain_count", "strict_zero_modes", "check_strainable", "strain_matrix",
           "strain_coefficients", "strained_lp", "select_rows", "container_walls",
           "analyse_strained", "median_gap", "smallest_gap", "DEFORMABLE_NOTE",
           "INITIAL_STEP_FLOOR"]

#: The note every deformable run carries.
DEFORMABLE_NOTE = ("deformable box: the LP loop with the strain columns and the strict Newton "
                   "stage (no contact pivots, no force clean-up LP)")
#: A pair whose selection would reach this fraction of half the shortest box vector makes the
#: bound halve (the minimum image must stay unique).
SAFE_REACH = 1.0 - 1e-9
#: Smallest first bound on displacements (mean diameters). From the fixed box's
#: (`calippso.ilp.INITIAL_STEP_FLOOR`, 1e-3) the first LPs of a deformable run on an LS input
#: reach their bound one after another, and each is solved cold while the bound grows by
#: `JamSettings.step_growth` (4); starting at 1.6e-2 skips two of them.
INITIAL_STEP_FLOOR = 1.6e-2
#: Bound on every strain variable per unit of b / W, with b the step bound and W the longest
#: box vector: the strain then moves a centre by a few b at most, relative to the pinned one.
STRAIN_BOUND = 1.0
#: `smallest_gap` looks at the walls within this many radii of a centre.
NEAR_WALL = 1.01


def strain_count(d: int) -> int:
    """Number of strain variables, d(d+1)/2."""
    return d * (d + 1) // 2


def strict_zero_modes(boundaries: Boundaries) -> int:
    """The 'zero modes' that make `calippso.geometry.contacts.isostaticity_gap` count a strictly
    isostatic network: the container's rigid motions (`Boundaries.zero_modes`; d translations
    in a periodic box) less the d_p(d_p+1)/2 − 1 degrees of freedom of the periodic axes'
    shape at a volume that does not grow (docs/theory.md). Periodic box:
    N_c = d (N_s − 1) + d(d+1)/2."""
    return boundaries.zero_modes + 1 - strain_count(boundaries.n_periodic)


def check_strainable(boundaries: Boundaries) -> None:
    """Raise ValueError (one line) for a container with no periodic axis: its box has no
    strain."""
    if not boundaries.periodic.any():
        raise ValueError(f"box='deformable' needs a periodic axis: the strain acts on the "
                         f"periodic axes and this container ({boundaries.describe()}) has "
                         f"none; use the fixed box")


def _off_diagonal(d: int) -> list[tuple[int, int]]:
    return [(a, b) for a in range(d) for b in range(a + 1, d)]


def _strain_columns(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """lᵀ ε r as a linear function of the strain variables (module docstring), shape
    (M, d(d+1)/2), for rows l and r, shape (M, d)."""
    d = left.shape[1]
    products = left * right
    columns = [products[:, a] - products[:, d - 1] for a in range(d - 1)]
    columns += [left[:, a] * right[:, b] + left[:, b] * right[:, a] for a, b in _off_diagonal(d)]
    columns.append(products[:, d - 1])
    return np.stack(columns, axis=1)


def strain_coefficients(vectors: np.ndarray, distances: np.ndarray,
                        periodic: np.ndarray | None = None) -> np.ndarray:
    """The strain columns of the pair rows: r ε r / |r| as a linear function of the strain
    variables (module docstring), shape (M, d_p(d_p+1)/2).

    Parameters
    ----------
    vectors : ndarray, shape (M, d)
        Pair vectors r_ij (length units).
    distances : ndarray, shape (M,)
        |r_ij|.
    periodic : ndarray, shape (d,), bool, optional
        The axes the strain acts on (`Boundaries.periodic`); None: every axis.
    """
    if periodic is not None:
        vectors = vectors[:, periodic]
    return _strain_columns(vectors / distances[:, None], vectors)


def strain_matrix(variables: np.ndarray, periodic: np.ndarray) -> np.ndarray:
    """The symmetric strain ε, shape (d, d), from the LP's strain variables (module
    docstring: diagonal differences, off-diagonal entries, trace) of the `periodic` axes
    (shape (d,), bool); zero in the rows and columns of the other axes."""
    axes = np.flatnonzero(periodic)
    k = axes.size
    block = np.zeros((k, k))
    diagonal = variables[:k - 1]
    block[np.arange(k - 1), np.arange(k - 1)] = diagonal
    block[k - 1, k - 1] = variables[-1] - diagonal.sum()
    for value, (a, b) in zip(variables[k - 1:-1], _off_diagonal(k)):
        block[a, b] = block[b, a] = value
    strain = np.zeros((periodic.size, periodic.size))
    strain[np.ix_(axes, axes)] = block
    return strain


def strain_scale(matrix: np.ndarray, periodic: np.ndarray) -> float:
    """e / b: the bound on every strain variable per unit of the step bound b,
    `STRAIN_BOUND` / W with W the longest periodic box vector (mean diameters; `periodic`
    shape (d,), bool)."""
    return STRAIN_BOUND / float(np.linalg.norm(matrix[:, periodic], axis=0).max())


def _images(positions: np.ndarray, matrix: np.ndarray, pairs: Pairs) -> np.ndarray:
    """The lattice vector m of every pair, r_ij = r_i − r_j + m_ij, shape (M, d): zero for a
    pair whose minimum image does not cross the boundary of the cell of `positions`."""
    shift = pairs.vectors - (positions[pairs.i] - positions[pairs.j])
    return np.rint(np.linalg.solve(matrix, shift.T)).T @ matrix.T


def strained_lp(pairs: Pairs, images: np.ndarray, walls: WallRows, n: int, bound: float,
                scale: float, fixed: np.ndarray, boundaries: Boundaries) -> LinearProgram:
    """The LP of one step (module docstring): the fixed box's LP of these rows
    (`calippso.lp.build_lp`, pairs then `walls`) with the strain columns of the periodic
    axes between the displacements s' (affine part included) and γ; the strain enters the
    pair rows whose image vector (`images`, shape (M, d)) is not zero. Strain variables are
    bounded by `scale` × `bound`, the trace by 0 above; `fixed` (N, d) are the pinned
    coordinates."""
    d, periodic = boundaries.d, boundaries.periodic
    lp = build_lp(pairs, n, d, bound, fixed, walls, zero_modes=strict_zero_modes(boundaries))
    k, moves = strain_count(boundaries.n_periodic), n * d
    across = np.flatnonzero(np.any(images != 0.0, axis=1))
    normals = pairs.vectors[across][:, periodic] / pairs.distances[across, None]
    strain = sp.csc_matrix((_strain_columns(normals, images[across][:, periodic]).ravel(),
                            (np.repeat(across, k), np.tile(np.arange(k), across.size))),
                           shape=(lp.n_rows, k))
    # the strain's CSC columns spliced in before γ's (both matrices are canonical)
    fixed_box, split = lp.matrix, lp.matrix.indptr[moves]
    matrix = sp.csc_matrix((
        np.concatenate([fixed_box.data[:split], strain.data, fixed_box.data[split:]]),
        np.concatenate([fixed_box.indices[:split], strain.indices,
                        fixed_box.indices[split:]]),
        np.concatenate([fixed_box.indptr[:moves + 1], split + strain.indptr[1:],
                        strain.nnz + fixed_box.indptr[moves + 1:]])),
        shape=(lp.n_rows, moves + k + 1))
    limit = np.full(k, bound)
    lower = np.concatenate([lp.col_lower[:moves], -limit * scale, lp.col_lower[moves:]])
    upper = np.concatenate([lp.col_upper[:moves], limit * scale, lp.col_upper[moves:]])
    upper[moves + k - 1] = 0.0            # the trace: the volume does not grow
    return replace(lp, matrix=matrix, col_lower=lower, col_upper=upper)


def select_rows(positions: np.ndarray, diameters: np.ndarray, matrix: np.ndarray,
                bound: float, boundaries: Boundaries, box: np.ndarray
                ) -> tuple[Pairs, np.ndarray, WallRows] | None:
    """Every pair that could come into contact in a step of bound b, its image vector
    (`_images`), and every particle–wall pair that could (`calippso.lp.select_walls`'s rule,
    with the same bound g on √Γ); None when that selection would reach beyond half the
    shortest box vector. A pair moves by at most 2√d b + √(2d_p² − 1) e |m| (e =
    `strain_scale` b bounds every strain variable, and √(2d_p² − 1) e the strain's operator
    norm on the d_p periodic axes, |ε_dd| ≤ d_p e through the trace); |m| is at most the
    periodic cell's diameter plus the cutoff. `matrix` is the search cell
    (`Boundaries.search_cell`), `box` (d,) the sides (those of the walls do not change)."""
    d, periodic = positions.shape[1], boundaries.periodic
    d_p = int(periodic.sum())
    absolute = 2.0 * np.sqrt(d) * bound
    per_image = np.sqrt(2.0 * d_p * d_p - 1.0) * strain_scale(matrix, periodic) * bound
    half = half_shortest_vector(matrix)
    widest = (float(np.linalg.norm(matrix[:, periodic], axis=0).sum())
              + SAFE_REACH * half)
    nearest = sheared_pairs_within(positions, diameters, matrix,
                                   min(SAFE_REACH * half, 1.5 * float(diameters.max())))
    if not len(nearest):
        return None
    near_images = _images(positions, matrix, nearest)
    reach = absolute + per_image * np.linalg.norm(near_images, axis=1)
    growth = float(np.min((nearest.distances + reach) / nearest.sigma))
    cutoff = growth * float(diameters.max()) + absolute + per_image * widest
    if cutoff >= SAFE_REACH * half:
        return None
    pairs = sheared_pairs_within(positions, diameters, matrix, cutoff)
    images = _images(positions, matrix, pairs)
    reach = absolute + per_image * np.linalg.norm(images, axis=1)
    keep = pairs.distances - reach <= growth * pairs.sigma
    return pairs.subset(keep), images[keep], container_walls(positions, diameters, boundaries,
                                                             box, bound, growth)


def container_walls(positions: np.ndarray, diameters: np.ndarray, boundaries: Boundaries,
                    box: np.ndarray, reach: float = 0.0, growth: float = 1.0) -> WallRows:
    """The particle–wall pairs within growth · σ_i/2 + reach of their wall
    (`calippso.geometry.walls.wall_rows_within`); none in a periodic box. Shapes: positions
    (N, d), diameters (N,), box (d,) the sides (length units)."""
    if boundaries.is_periodic:
        return empty_walls(positions.shape[1])
    return wall_rows_within(positions, diameters, box, boundaries, reach, growth)


def analyse_strained(lp: LinearProgram, solution: LPSolution, settings: JamSettings,
                     scale: float, offered_warm_start: bool) -> Step:
    """An LP's answer read as the fixed box's (`calippso.step.analyse` on its displacement
    and γ columns), with the strain's share: the largest move is that of a stable particle
    or of a strain variable (over `scale`: in units of the step bound), and a strain
    variable at its bound with a binding reduced cost holds the step back too."""
    moves = lp.n * lp.d
    k = lp.n_cols - moves - 1
    kept = np.r_[0:moves, moves + k]
    taken = analyse(replace(lp, matrix=lp.matrix[:, kept], col_lower=lp.col_lower[kept],
                            col_upper=lp.col_upper[kept]),
                    replace(solution, x=solution.x[kept]), settings,
                    offered_warm_start=offered_warm_start)
    strain = solution.x[moves:moves + k]
    largest = max(taken.max_displacement, float(np.abs(strain).max()) / scale)
    held = taken.held_by_bound
    pressed = at_bound(np.abs(strain), lp.step_bound * scale)
    if not held and pressed.any() and solution.duals.size and solution.duals.max() > 0:
        reduced = (lp.matrix[:, moves:moves + k].T @ solution.duals)[pressed]
        held = bool(np.any(np.abs(reduced) > BINDING_REDUCED_COST * solution.duals.max()))
    return replace(taken, lp=lp, solution=solution, max_displacement=largest,
                   max_contacting=largest, held_by_bound=held)


def median_gap(positions: np.ndarray, diameters: np.ndarray, matrix: np.ndarray) -> float:
    """Median over particles of the relative gap to the nearest neighbour (or 1 when a
    particle has none within 1.5 diameters)."""
    cutoff = min(SAFE_REACH * half_shortest_vector(matrix), 1.5 * float(diameters.max()))
    pairs = sheared_pairs_within(positions, diameters, matrix, cutoff)
    nearest = np.full(positions.shape[0], 1.0)
    np.minimum.at(nearest, pairs.i, pairs.distances - pairs.sigma)
    np.minimum.at(nearest, pairs.j, pairs.distances - pairs.sigma)
    return float(np.median(nearest))


def smallest_gap(positions: np.ndarray, diameters: np.ndarray, matrix: np.ndarray,
                 boundaries: Boundaries | None = None, box: np.ndarray | None = None) -> float:
    """The smallest relative gap of the pairs within 1.01 diameters, and of the particles
    to the container's walls (`boundaries`, sides `box` (d,); None: a periodic box)."""
    cutoff = min(SAFE_REACH * half_shortest_vector(matrix), float(diameters.max()) * 1.01)
    gap = sheared_pairs_within(positions, diameters, matrix, cutoff).smallest_gap()
    if boundaries is None or boundaries.is_periodic:
        return gap
    return min(gap, container_walls(positions, diameters, boundaries, box,
                                    growth=NEAR_WALL).smallest_gap())
