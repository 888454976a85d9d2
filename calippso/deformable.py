"""The deformable box: CALiPPSO with the box's strain in every LP, towards strict jamming.

`jam(packing, box="deformable")` runs this loop. Each LP has, besides γ = Γ − 1, a
symmetric strain ε of the box (d(d+1)/2 variables) and the displacements s'_i of the centres,
their affine part included: the box vectors become (I + ε) H and the centres r_i + s'_i.
A pair's separation is r_ij = r_i − r_j + m_ij, with m_ij a lattice vector (zero unless the
pair's minimum image crosses the boundary), and it becomes r_ij + s'_i − s'_j + ε m_ij
exactly. Its linearised non-overlap condition is that of the fixed box with the strain's
share added,

    n_ij·(s'_i − s'_j) + n_ijᵀ ε m_ij − γ σ_ij²/(2|r_ij|) ≥ −(|r_ij|² − σ_ij²)/(2|r_ij|),

and the box's volume may not grow, tr ε ≤ 0. The LP maximises γ: at a volume that does not
grow, that is the growth of the packing fraction (Donev, Torquato, Stillinger & Connelly,
J. Comput. Phys. 197, 139 (2004); Torquato & Jiao, Phys. Rev. E 82, 061302 (2010)). This
is the affine form (centres (I + ε) r_i + s_i) with s'_i = s_i + ε r_i; written so, the strain
columns hold entries on the rows of the pairs across the boundary only (about a sixth of the
rows at N = 1024 in d = 3), where the affine form puts them on every row, and an LP costs
about as much as the fixed box's.

The strain variables are the diagonal differences ε_μμ (μ < d), the off-diagonal entries
ε_μν (μ < ν) and the trace t = tr ε, with ε_dd = t − Σ_{μ<d} ε_μμ; the volume condition is
then the column bound t ≤ 0 and the LP keeps one row per pair (so that the basis of one LP
warm-starts the next, as in the fixed box). Each s'_iμ is bounded by the step bound b, every
strain variable by e = `STRAIN_BOUND` b / W (W the longest box vector), and the centres are
taken in the cell centred on the pinned particle, so that the affine part fits the bound; a
pair then moves by at most 2√d b + √(2d² − 1) e |m_ij| in a step (`_select`).

At the optimum, the strain columns say that the contact stress Σ μ_ij r_ij r_ijᵀ/|r_ij| is
p I, with p the multiplier of t ≤ 0: the stress is isotropic and the pressure is the
volume's multiplier (`JammingResult.stress`, docs/theory.md).

Once an LP's step is small (largest displacement below `JamSettings.newton_start`) and its
contact network has the strict count, N_c = d (N_s − 1) + d(d+1)/2, the strict Newton stage
(`calippso.certification.strict_newton`) solves that network's contact equations in the positions, the
strain and Γ, and stops the loop where it certifies the point (``newton=False`` turns it
off). What the fixed-box loop does and this one does not: the network-first stage, the
contact pivots, the force clean-up LP, checkpoints and walls; the notes say so.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from scipy.optimize import linprog
from scipy.sparse.linalg import lsmr

from .geometry.contacts import contact_mask, force_balance, isostaticity_gap
from .errors import JammingError
from .history import History, StopReason, status_sentence
from .lp import LinearProgram
from .geometry.neighbors import Pairs
from .certification.certificate import NEWTON_OVERLAP_TOLERANCE
from .geometry.contact_network import GEOMETRIC_CONTACT_GAP, ROUNDOFF_SHRINK_MARGIN
from .geometry.packing import Packing
from .geometry.periodic import lattice_minimum_image, lattice_wrap
from .geometry.rattlers import remove_rattlers
from .result import JammingResult
from .settings import JamSettings
from .geometry.sheared_search import half_shortest_vector, sheared_pairs_within
from .solvers.policy import LPFailed, SolverPolicy, next_warm_start
from .stages.lp_step import VANISHING_STEP_FRACTION
from .step import BINDING_REDUCED_COST, at_bound
from .certification.strict_newton import StrictRefinement, refine_strict, strict_unknowns
from .geometry.walls import EMPTY_WALLS

__all__ = ["jam_deformable", "strain_count", "strict_zero_modes", "strain_matrix",
           "strain_coefficients", "DEFORMABLE_NOTE"]

#: The note every deformable run carries.
DEFORMABLE_NOTE = ("deformable box: LP loop and strict Newton stage (no network-first or "
                   "pivot stage, no force clean-up LP)")
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
#: The strict rows have a floppy mode when the smallest eigenvalue of AᵀA is below this
#: times its mean diagonal (as `calippso.categories.FLOPPY_EIGENVALUE`).
FLOPPY_EIGENVALUE = 1e-12
#: Up to this many columns the stiffness spectrum is computed densely.
DENSE_STIFFNESS = 200
#: Passes that move rattlers out of overlaps after the strict Newton stage, and the gap
#: (relative to the pair's contact distance) that each pass leaves.
RATTLER_PASSES = 16
RATTLER_CLEARANCE = 1e-12
#: The final search for touching pairs reaches this fraction beyond the largest diameter.
NEAR_CONTACT = 1e-6
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


def strain_count(d: int) -> int:
    """Number of strain variables, d(d+1)/2."""
    return d * (d + 1) // 2


def strict_zero_modes(d: int) -> int:
    """The 'zero modes' that make `calippso.geometry.contacts.isostaticity_gap` count a strictly
    isostatic network, N_c = d (N_s − 1) + d(d+1)/2: the d translations less the
    d(d+1)/2 − 1 degrees of freedom of a box whose volume does not grow (docs/theory.md)."""
    return d + 1 - strain_count(d)


def _off_diagonal(d: int) -> list[tuple[int, int]]:
    return [(a, b) for a in range(d) for b in range(a + 1, d)]


def strain_coefficients(vectors: np.ndarray, distances: np.ndarray) -> np.ndarray:
    """The strain columns of the pair rows: r ε r / |r| as a linear function of the strain
    variables (module docstring), shape (M, d(d+1)/2).

    Parameters
    ----------
    vectors : ndarray, shape (M, d)
        Pair vectors r_ij (length units).
    distances : ndarray, shape (M,)
        |r_ij|.
    """
    d = vectors.shape[1]
    squares = vectors**2 / distances[:, None]
    columns = [squares[:, a] - squares[:, d - 1] for a in range(d - 1)]
    columns += [2.0 * vectors[:, a] * vectors[:, b] / distances for a, b in _off_diagonal(d)]
    columns.append(squares[:, d - 1])
    return np.stack(columns, axis=1)


def strain_matrix(variables: np.ndarray, d: int) -> np.ndarray:
    """The symmetric strain ε, shape (d, d), from the LP's strain variables (module
    docstring: diagonal differences, off-diagonal entries, trace)."""
    strain = np.zeros((d, d))
    diagonal = variables[:d - 1]
    strain[np.arange(d - 1), np.arange(d - 1)] = diagonal
    strain[d - 1, d - 1] = variables[-1] - diagonal.sum()
    for value, (a, b) in zip(variables[d - 1:-1], _off_diagonal(d)):
        strain[a, b] = strain[b, a] = value
    return strain


def _strain_scale(matrix: np.ndarray) -> float:
    """e / b: the bound on every strain variable per unit of the step bound b,
    `STRAIN_BOUND` / W with W the longest box vector (mean diameters)."""
    return STRAIN_BOUND / float(np.linalg.norm(matrix, axis=0).max())


def _images(positions: np.ndarray, matrix: np.ndarray, pairs: Pairs) -> np.ndarray:
    """The lattice vector m of every pair, r_ij = r_i − r_j + m_ij, shape (M, d): zero for a
    pair whose minimum image does not cross the boundary of the cell of `positions`."""
    shift = pairs.vectors - (positions[pairs.i] - positions[pairs.j])
    return np.rint(np.linalg.solve(matrix, shift.T)).T @ matrix.T


def _image_strain_coefficients(normals: np.ndarray, images: np.ndarray) -> np.ndarray:
    """nᵀ ε m as a linear function of the strain variables (module docstring), shape
    (M, d(d+1)/2), for unit normals n and image vectors m, shape (M, d)."""
    d = normals.shape[1]
    products = normals * images
    columns = [products[:, a] - products[:, d - 1] for a in range(d - 1)]
    columns += [normals[:, a] * images[:, b] + normals[:, b] * images[:, a]
                for a, b in _off_diagonal(d)]
    columns.append(products[:, d - 1])
    return np.stack(columns, axis=1)


def _build_lp(pairs: Pairs, images: np.ndarray, n: int, d: int, bound: float,
              strain_scale: float, pinned: int | None) -> LinearProgram:
    """The LP of one step (module docstring): columns s' (N d, affine part included), the
    strain variables, γ; one row per pair, with the strain on the rows whose image vector
    (`images`, shape (M, d)) is not zero. Displacements are bounded by `bound`, strain
    variables by `strain_scale` × `bound`."""
    m, k = len(pairs), strain_count(d)
    normals = pairs.vectors / pairs.distances[:, None]
    coordinate = np.arange(d)
    across = np.flatnonzero(np.any(images != 0.0, axis=1))
    strain = _image_strain_coefficients(normals[across], images[across])
    rows = np.concatenate([np.repeat(np.arange(m), 2 * d + 1), np.repeat(across, k)])
    columns = np.concatenate([
        np.concatenate([pairs.i[:, None] * d + coordinate, pairs.j[:, None] * d + coordinate,
                        np.full((m, 1), n * d + k)], axis=1).ravel(),
        np.tile(n * d + np.arange(k), across.size)])
    values = np.concatenate([
        np.concatenate([normals, -normals,
                        -(pairs.sigma**2 / (2.0 * pairs.distances))[:, None]], axis=1).ravel(),
        strain.ravel()])
    matrix = sp.csc_matrix((values, (rows, columns)), shape=(m, n * d + k + 1))
    row_lower = -(pairs.distances - pairs.sigma) * (pairs.distances + pairs.sigma) / (
        2.0 * pairs.distances)
    col_lower = np.full(n * d + k + 1, -bound)
    col_upper = np.full(n * d + k + 1, bound)
    col_lower[n * d:n * d + k] *= strain_scale
    col_upper[n * d:n * d + k] *= strain_scale
    col_upper[n * d + k - 1] = 0.0            # the trace: the volume does not grow
    if pinned is not None:
        col_lower[pinned * d:(pinned + 1) * d] = 0.0
        col_upper[pinned * d:(pinned + 1) * d] = 0.0
    col_lower[-1], col_upper[-1] = -1.0, np.inf
    return LinearProgram(matrix, row_lower, col_lower, col_upper, pairs, n, d, bound,
                         EMPTY_WALLS, strict_zero_modes(d))


def _select(positions, diameters, matrix, bound) -> tuple[Pairs, np.ndarray] | None:
    """Every pair that could come into contact in a step of bound b, and its image vector
    (`_images`); None when that selection would reach beyond half the shortest box vector.
    A pair moves by at most 2√d b + √(2d² − 1) e |m| (e = `_strain_scale` b bounds every
    strain variable, and √(2d² − 1) e the strain's operator norm, |ε_dd| ≤ d e through the
    trace); |m| is at most the cell's diameter plus the cutoff."""
    d = positions.shape[1]
    absolute = 2.0 * np.sqrt(d) * bound
    per_image = np.sqrt(2.0 * d * d - 1.0) * _strain_scale(matrix) * bound
    half = half_shortest_vector(matrix)
    widest = float(np.linalg.norm(matrix, axis=0).sum()) + SAFE_REACH * half
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
    return pairs.subset(keep), images[keep]


def _median_gap(positions, diameters, matrix) -> float:
    """Median over particles of the relative gap to the nearest neighbour (or 1 when a
    particle has none within 1.5 diameters)."""
    cutoff = min(SAFE_REACH * half_shortest_vector(matrix), 1.5 * float(diameters.max()))
    pairs = sheared_pairs_within(positions, diameters, matrix, cutoff)
    nearest = np.full(positions.shape[0], 1.0)
    np.minimum.at(nearest, pairs.i, pairs.distances - pairs.sigma)
    np.minimum.at(nearest, pairs.j, pairs.distances - pairs.sigma)
    return float(np.median(nearest))


def _smallest_gap(positions, diameters, matrix) -> float:
    cutoff = min(SAFE_REACH * half_shortest_vector(matrix), float(diameters.max()) * 1.01)
    return sheared_pairs_within(positions, diameters, matrix, cutoff).smallest_gap()


def jam_deformable(packing: Packing, settings: JamSettings, callback=None) -> JammingResult:
    """Jam `packing` with the box's strain in every LP (module docstring).

    Parameters
    ----------
    packing : Packing
        Periodic along every axis; rectangular or sheared (`Packing.box_matrix`).
    settings : JamSettings
        The loop's tolerances, bounds, backend and contact threshold (the stages that this
        loop does not run ignore their settings).
    callback : callable, optional
        Called after every LP with the record as a dict plus "iteration" and "packing";
        returning True stops the run.

    Returns
    -------
    JammingResult
        With ``box_mode="deformable"``, the final (possibly sheared) box, the contact forces
        and the contact stress tensor (`JammingResult.stress`).

    Raises
    ------
    ValueError
        A box with walls or a cylinder.
    JammingError
        Every backend failed on an LP, or the box became too small for any step.
    """
    if not packing.boundaries.is_periodic:
        raise ValueError("box='deformable' needs a periodic box; walls and cylinders stay "
                         "where they are (use the fixed box)")
    start = time.perf_counter()
    n, d = packing.n, packing.d
    input_gap = _smallest_gap(packing.positions / packing.mean_diameter,
                              packing.diameters / packing.mean_diameter,
                              packing.lattice / packing.mean_diameter)
    if input_gap < -settings.overlap_tolerance:
        raise ValueError(f"the input overlaps: the deepest relative gap is {input_gap:.3e}, "
                         f"beyond overlap_tolerance {settings.overlap_tolerance:g}")
    scale = packing.mean_diameter
    positions = packing.positions / scale
    diameters = packing.diameters / scale
    matrix = packing.lattice / scale
    phi_input = packing.phi
    history = History(d, start, settings.verbose, zero_modes=strict_zero_modes(d))
    history.note(DEFORMABLE_NOTE)
    policy = SolverPolicy(settings)
    pinned = 0 if settings.pin else None
    gap = _median_gap(positions, diameters, matrix)
    bound = float(np.clip(settings.initial_step if settings.initial_step is not None
                          else max(gap, INITIAL_STEP_FLOOR), settings.min_step,
                          settings.max_step))
    basis, reason, last, newton, tried = None, StopReason.MAX_ITERS, None, None, set()

    def current(x, sigma, h) -> Packing:
        return Packing.sheared(x * scale, sigma * scale, h * scale)

    def fail(message: str) -> JammingError:
        return JammingError(message, packing=current(positions, diameters, matrix),
                            history=history.to_array())

    while history.lps_solved < settings.max_iters:
        step = bound
        # the centres in one cell (`_select` bounds the image vectors by its diameter),
        # centred on the pinned particle (the strain's affine move then fits the bound)
        origin = (positions[pinned] - 0.5 * matrix.sum(axis=1) if pinned is not None
                  else np.zeros(d))
        positions = lattice_wrap(positions - origin, matrix) + origin
        while True:
            pairs = _select(positions, diameters, matrix, step)
            if pairs is not None:
                break
            step *= 0.5
            if step < settings.min_step * VANISHING_STEP_FRACTION:
                raise fail("box too small: even a vanishing step would need pairs beyond half "
                           "the shortest box vector")
        strain_scale = _strain_scale(matrix)

        def build(b: float, selected=pairs, first=step) -> LinearProgram:
            rows = selected if b == first else _select(positions, diameters, matrix, b)
            return _build_lp(*rows, n, d, b, strain_scale, pinned)

        try:
            solved = policy.solve(build, step, basis, history.lps_solved + 1)
        except LPFailed as error:
            raise fail(str(error)) from None
        if solved.note is not None:
            history.note(solved.note)
        lp, solution = solved.lp, solved.solution
        taken = _analyse(lp, solution, settings, strain_scale)
        strain = strain_matrix(solution.x[n * d:-1], d)
        deformation = np.eye(d) + strain
        new_positions = positions + solution.x[:n * d].reshape(n, d)
        new_matrix = deformation @ matrix
        new_diameters = diameters * np.sqrt(1.0 + solution.gamma)
        new_positions = lattice_wrap(new_positions, new_matrix)
        min_gap = _smallest_gap(new_positions, new_diameters, new_matrix)
        positions, diameters, matrix = new_positions, new_diameters, new_matrix
        basis = _warm_start(solution, solved.warm_start is not None, taken, lp.step_bound)
        record = history.add_lp(
            stage="lp", solver_time=solution.seconds + policy.take_discarded_seconds(),
            gamma=solution.gamma, max_displacement=taken["max_move"], rows=lp.n_rows,
            step_bound=lp.step_bound, n_contacts=taken["n_contacts"],
            n_stable=int(n - taken["rattlers"].sum()), force_balance=taken["balance"],
            min_gap=min_gap, phi=current(positions, diameters, matrix).phi,
            ipm_iterations=solution.ipm_iterations)
        last = (lp, solution, taken)
        if callback is not None and callback({**record.as_dict(),
                                              "iteration": history.lps_solved,
                                              "packing": current(positions, diameters,
                                                                 matrix)}):
            reason = StopReason.STOPPED_BY_CALLBACK
            break
        if settings.newton and taken["max_move"] < settings.newton_start:
            newton = _strict_newton(positions, diameters, matrix, lp.pairs, taken, tried,
                                    settings.overlap_tolerance)
            if newton is not None:
                positions, diameters, matrix = (newton.refinement.positions,
                                                newton.refinement.diameters,
                                                newton.refinement.matrix)
                _record_newton(history, newton, current(positions, diameters, matrix).phi)
                reason = StopReason.CONVERGED
                break
        if (record.sqrt_gamma_minus_1 < settings.tol_gamma
                and taken["max_move"] < settings.tol_s
                and taken["max_move"] < 0.5 * lp.step_bound and not taken["held"]):
            reason = StopReason.CONVERGED
            break
        if history.stalled(settings.tol_gamma):
            reason = StopReason.STALLED
            break
        if (settings.time_limit is not None
                and time.perf_counter() - start >= settings.time_limit):
            reason = StopReason.TIME_LIMIT
            break
        bound = _next_bound(lp.step_bound, taken, settings)
    if last is None:
        raise fail(f"no LP was solved (max_iters = {settings.max_iters})")
    return _result(positions, diameters, matrix, scale, last, reason, history, start,
                   phi_input, settings, newton)


def _analyse(lp: LinearProgram, solution, settings: JamSettings,
             strain_scale: float) -> dict:
    """Contacts, rattlers, forces and their balance, the largest move of a stable particle
    or of the strain (a strain variable over `strain_scale`: in units of the step bound),
    whether the bound held the step back."""
    n, d = lp.n, lp.d
    rows = np.flatnonzero(contact_mask(solution.duals, settings.contact_threshold))
    pairs = lp.pairs
    rattlers, kept = remove_rattlers(n, d, pairs.i[rows], pairs.j[rows])
    rows = rows[kept]
    forces = 0.5 * solution.duals[rows]
    normals = pairs.vectors[rows] / pairs.distances[rows, None]
    balance = force_balance(n, pairs.i[rows], pairs.j[rows], normals, forces, ~rattlers)
    s = solution.x[:n * d].reshape(n, d)
    strain = np.abs(solution.x[n * d:-1]).max(initial=0.0) / strain_scale
    moving = s[~rattlers] if (~rattlers).any() else s
    return {"rows": rows, "rattlers": rattlers, "forces": forces, "balance": balance,
            "max_move": float(max(np.abs(moving).max(initial=0.0), strain)),
            "n_contacts": int(rows.shape[0]),
            "stable_fraction": float(np.count_nonzero(~rattlers)) / n,
            "held": _held(lp, solution, strain_scale)}


def _held(lp: LinearProgram, solution, strain_scale: float) -> bool:
    """Whether a bound limited γ: a displacement or a strain variable at its bound with a
    reduced cost above `BINDING_REDUCED_COST` × the largest dual (`calippso.step.
    held_by_bound`, with the strain's own bound)."""
    if solution.duals.size == 0 or not solution.duals.max() > 0:
        return False
    n_moves = lp.n * lp.d
    x = solution.x[:-1]
    limits = np.full(x.shape[0], lp.step_bound)
    limits[n_moves:] *= strain_scale
    free = lp.col_upper[:-1] > lp.col_lower[:-1]
    pressed = free & at_bound(np.abs(x), limits)
    if not pressed.any():
        return False
    reduced = (lp.matrix.T @ solution.duals)[:-1]
    return bool(np.any(np.abs(reduced[pressed]) > BINDING_REDUCED_COST
                       * float(solution.duals.max())))


def _warm_start(solution, offered: bool, taken: dict, bound: float):
    """The basis the next LP starts from (`calippso.solvers.policy.next_warm_start`), or None
    for a cold start: here only after a warm start that failed or a step that reached its
    bound (the bound then grows and the next optimum is far). The fixed box's rule, cold
    after any move of half the bound, would solve one LP in eight cold along the slide of a
    deformable box, at ten times the cost of a warm start from the last basis."""
    moved = taken["max_move"] if at_bound(taken["max_move"], bound) else 0.0
    return next_warm_start(solution, offered, moved, bound)


def _next_bound(step: float, taken: dict, settings: JamSettings) -> float:
    """The fixed box's rule (`calippso.ilp.next_step_bound`) on the largest move of a stable
    particle or of the strain."""
    if at_bound(taken["max_move"], step) or taken["stable_fraction"] < 0.5:
        proposed = step * settings.step_growth if at_bound(taken["max_move"], step) else step
    elif taken["held"]:
        proposed = max(step, settings.step_margin * taken["max_move"])
    else:
        proposed = settings.step_margin * taken["max_move"]
    return float(np.clip(proposed, settings.min_step, settings.max_step))


@dataclass(frozen=True, eq=False)
class _NewtonPoint:
    """A network of an LP solved by `calippso.certification.strict_newton.refine_strict` and certified."""

    refinement: StrictRefinement
    i: np.ndarray
    j: np.ndarray
    rattlers: np.ndarray
    seconds: float


def _strict_newton(positions: np.ndarray, diameters: np.ndarray, matrix: np.ndarray,
                   pairs: Pairs, taken: dict, tried: set,
                   round_off: float) -> _NewtonPoint | None:
    """The strictly jammed point of the LP's network (`calippso.certification.strict_newton`), when it has
    the strict count, was not refused before, and its Newton solution is certified: positive
    forces, no pair of stable particles that is no contact overlapping beyond `round_off`
    (the LPs' own feasibility round-off; the result's diameters are scaled down by it) and
    no rattler overlapped beyond it (`_clear_rattlers`). None otherwise. A network refused for its own sake (no
    solution, a non-positive force, stable particles overlapping) joins `tried`; one refused
    for a rattler that its cage overlaps is tried again after the next LP, which moves the
    rattler."""
    began = time.perf_counter()
    rows, rattlers = taken["rows"], taken["rattlers"]
    n_stable = int(rattlers.size - rattlers.sum())
    if rows.shape[0] != strict_unknowns(n_stable, positions.shape[1]):
        return None
    i, j = pairs.i[rows], pairs.j[rows]
    keys = np.sort(np.minimum(i, j) * positions.shape[0] + np.maximum(i, j))
    key = keys.tobytes()
    if key in tried:
        return None
    vectors = lattice_minimum_image(positions[i] - positions[j], matrix)
    refined = refine_strict(positions, diameters, matrix, i, j, vectors, ~rattlers)
    if refined is None or not refined.positive:
        tried.add(key)
        return None
    moved, stable_overlap = _clear_rattlers(refined.positions, refined.diameters,
                                            refined.matrix, keys, rattlers, round_off)
    if moved is None:
        if stable_overlap:
            tried.add(key)
        return None
    return _NewtonPoint(replace(refined, positions=moved), i, j, rattlers,
                        time.perf_counter() - began)


def _clear_rattlers(positions: np.ndarray, diameters: np.ndarray, matrix: np.ndarray,
                    keys: np.ndarray, rattlers: np.ndarray,
                    round_off: float = NEWTON_OVERLAP_TOLERANCE
                    ) -> tuple[np.ndarray | None, bool]:
    """The positions with every rattler that a pair overlaps beyond `round_off` moved out
    of it along the pair's normal (a rattler that
    touched its cage after the last LP is overlapped by the cage's small move); None when a
    rattler is still overlapped after `RATTLER_PASSES` passes, or when two stable particles
    that are no contact overlap beyond `round_off` (then the flag is True). `keys` are the
    contacts' keys min(i, j) N + max(i, j)."""
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


def _record_newton(history: History, newton: _NewtonPoint, phi: float) -> None:
    """The history record and the note of a certified strict Newton point."""
    solution = newton.refinement
    n_stable = int(newton.rattlers.size - newton.rattlers.sum())
    history.add_newton(seconds=newton.seconds, sqrt_gamma_minus_1=solution.sqrt_gamma_minus_1,
                       max_displacement=solution.max_displacement,
                       n_contacts=newton.i.shape[0], n_stable=n_stable,
                       force_balance=float("nan"), min_gap=float("nan"), phi=phi)
    history.note(f"strict contact equations (positions, strain, growth) solved by Newton "
                 f"({solution.iterations} iterations, {solution.factorizations} "
                 f"factorisation(s), residual {solution.residual:.0e}) after "
                 f"{history.lps_solved} LPs")


def _result(positions, diameters, matrix, scale, last, reason, history, start, phi_input,
            settings, newton: _NewtonPoint | None = None) -> JammingResult:
    """The result: the final packing (shrunk by round-off overlaps, if any), its contact
    network and forces (those of the strict Newton point, else `_final_network`), the
    stress tensor, the strain certificate in the notes."""
    lp, solution, taken = last
    gap = _smallest_gap(positions, diameters, matrix)
    if gap < 0:
        diameters = diameters * (1.0 + gap) * (1.0 - ROUNDOFF_SHRINK_MARGIN)
        history.note(f"diameters scaled by 1 - {-gap:.1e} to remove round-off overlaps")
    packing = Packing.sheared(positions * scale, diameters * scale, matrix * scale)
    certified = False
    if newton is not None:
        i, j, rattlers = newton.i, newton.j, newton.rattlers
        forces = newton.refinement.forces / newton.refinement.forces.mean()
        balance = _balance_of(packing, i, j, forces, rattlers)
        certified = balance <= settings.balance_tolerance
    if not certified:
        pairs, rows = lp.pairs, taken["rows"]
        i, j, forces, rattlers, balance = _final_network(packing, pairs.i[rows],
                                                         pairs.j[rows], taken["forces"],
                                                         history)
    vectors = packing.minimum_image(packing.positions[i] - packing.positions[j])
    stress = _stress(vectors, forces, packing.volume)
    n_stable = int(rattlers.size - rattlers.sum())
    gap_count = isostaticity_gap(i.shape[0], n_stable, lp.d, strict_zero_modes(lp.d))
    history.note(_certificate_note(lp, solution, stress))
    category = None
    if certified:
        reason, category = StopReason.CERTIFIED_NEWTON, "strict"
        history.note("strictly jammed: positive forces in balance with an isotropic stress, "
                     "and a non-singular Jacobian of the strict contact equations")
    elif reason == StopReason.CONVERGED:
        if n_stable == 0 or gap_count < 0 or balance > settings.balance_tolerance:
            reason = StopReason.NOT_RIGID
        else:
            category = _strict_test(packing, i, j, forces, rattlers, history)
            if category is not None and category != "strict":
                reason = StopReason.NOT_RIGID
    status = status_sentence(reason, history.lps_solved, history.last_step(), n_stable,
                             gap_count, history.notes)
    return JammingResult(
        packing=packing, contacts=np.stack([i, j], axis=1).astype(np.int64),
        forces=forces, rattlers=rattlers, converged=reason.jammed, status=status,
        iterations=history.lps_solved, history=history.to_array(),
        wall_time=time.perf_counter() - start, force_balance=balance,
        dual_normalization=float(solution.duals @ lp.gamma_coefficients),
        solver=solution.solver, stop_reason=reason, notes=list(history.notes),
        phi_input=phi_input, box_mode="deformable", stress=stress, category=category)


def _strict_test(packing: Packing, i: np.ndarray, j: np.ndarray, forces: np.ndarray,
                 rattlers: np.ndarray, history: History) -> str | None:
    """The jamming category of the final packing: "strict" from the network's own
    certificate (`_floppy_strict_rows`), else from the linear test of `calippso.categories`
    on the network and every other pair that touches (a note when it is not "strict");
    None when that test could not decide (a note says why).

    The certificate: the forces are positive on every contact and in balance with an
    isotropic stress of positive pressure (`_final_network`), so by Stiemke's theorem no
    first-order motion of the strict test opens a contact; when the strict rows have no
    floppy mode either, the packing is strictly jammed (docs/theory.md, Jamming categories).
    """
    if np.all(forces > 0) and not _floppy_strict_rows(packing, i, j, rattlers):
        history.note("strictly jammed: positive forces with an isotropic stress, and no "
                     "floppy mode of the strict rows")
        return "strict"
    from .categories import jamming_category
    from .geometry.touching import touching_outside_network

    contacts = np.stack([i, j], axis=1)
    touching = touching_outside_network(packing, contacts, rattlers)
    every = JammingResult(packing=packing, contacts=np.concatenate([contacts, touching.pairs]),
                          forces=np.zeros(0), rattlers=rattlers, converged=False, status="",
                          iterations=0)
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


def _floppy_strict_rows(packing: Packing, i: np.ndarray, j: np.ndarray,
                        rattlers: np.ndarray) -> bool:
    """Whether the strict rows of the network (the contacts with the strain columns, and
    the volume row) have a floppy mode: a motion of the stable particles (one pinned) and
    the strain that keeps every row at zero. The smallest eigenvalue of AᵀA is zero, up to
    `FLOPPY_EIGENVALUE` × its mean diagonal, exactly when one exists."""
    from scipy.sparse.linalg import eigsh

    n, d = packing.n, packing.d
    k = strain_count(d)
    stable = np.flatnonzero(~rattlers)
    column = np.full(n, -1, dtype=np.int64)
    column[stable] = d * np.arange(stable.size)
    vectors = packing.minimum_image(packing.positions[i] - packing.positions[j])
    distances = np.linalg.norm(vectors, axis=1)
    normals = vectors / distances[:, None]
    m, n_moves = i.shape[0], d * stable.size
    axis = np.arange(d)
    rows = np.concatenate([np.repeat(np.arange(m), d), np.repeat(np.arange(m), d),
                           np.repeat(np.arange(m), k), [m]])
    cols = np.concatenate([(column[i][:, None] + axis).ravel(),
                           (column[j][:, None] + axis).ravel(),
                           np.tile(n_moves + np.arange(k), m), [n_moves + k - 1]])
    values = np.concatenate([normals.ravel(), -normals.ravel(),
                             strain_coefficients(vectors, distances).ravel(), [-1.0]])
    matrix = sp.csr_matrix((values, (rows, cols)), shape=(m + 1, n_moves + k))
    free = np.setdiff1d(np.arange(n_moves + k), np.arange(d))    # the first stable pinned
    stiffness = (matrix[:, free].T @ matrix[:, free]).tocsc()
    scale = float(stiffness.diagonal().mean())
    if free.size <= DENSE_STIFFNESS:
        smallest = float(np.linalg.eigvalsh(stiffness.toarray())[0])
    else:
        smallest = float(eigsh(stiffness, k=1, sigma=-1e-3 * FLOPPY_EIGENVALUE * scale,
                               which="LM", return_eigenvectors=False)[0])
    return smallest <= FLOPPY_EIGENVALUE * scale


def _final_network(packing: Packing, i: np.ndarray, j: np.ndarray, forces: np.ndarray,
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


def _equilibrium(packing: Packing, i: np.ndarray, j: np.ndarray,
                 rattlers: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """The matrix whose null space holds the forces f in equilibrium on every stable particle
    with an isotropic stress: d rows per particle (Σ f n), then the deviatoric stress
    (the strain columns but the trace, `strain_coefficients`); and the unit normals."""
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
    matrix, _ = _equilibrium(packing, i, j, rattlers)
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
    _, normals = _equilibrium(packing, i, j, rattlers)
    return force_balance(packing.n, i, j, normals, forces, ~rattlers)


def _stress(vectors: np.ndarray, forces: np.ndarray, volume: float) -> np.ndarray:
    """Σ_k f_k |r_k| n_k n_kᵀ / V over the contacts, shape (d, d)."""
    distances = np.linalg.norm(vectors, axis=1)
    stress = np.einsum("k,ka,kb->ab", forces / distances, vectors, vectors) / volume
    return 0.5 * (stress + stress.T)


def _certificate_note(lp: LinearProgram, solution, stress: np.ndarray) -> str:
    """The strain certificate of the last LP: the anisotropy of its own contact stress
    Σ μ r rᵀ/|r| (over every row), and its pressure against the volume's multiplier (the
    reduced cost of the trace column); then that of the final forces (`stress`)."""
    d, pairs = lp.d, lp.pairs
    lp_stress = np.einsum("k,ka,kb->ab", solution.duals / pairs.distances, pairs.vectors,
                          pairs.vectors)
    lp_pressure = float(np.trace(lp_stress)) / d
    volume_multiplier = float((lp.matrix.T @ solution.duals)[lp.n * d + strain_count(d) - 1])
    if not lp_pressure > 0:
        return "strain certificate: the last LP has no contact stress"
    anisotropy = float(np.abs(lp_stress - lp_pressure * np.eye(d)).max()) / lp_pressure
    mismatch = abs(volume_multiplier - lp_pressure) / lp_pressure
    final = float(np.trace(stress)) / d
    final_anisotropy = (float(np.abs(stress - final * np.eye(d)).max()) / final if final > 0
                        else float("nan"))
    return (f"strain certificate of the last LP: stress anisotropy {anisotropy:.1e}, volume "
            f"multiplier = virial pressure to {mismatch:.1e}; final forces: stress "
            f"anisotropy {final_anisotropy:.1e}")
