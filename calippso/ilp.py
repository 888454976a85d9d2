"""The CALiPPSO loop: iterate linear programs until the packing is jammed.

Each iteration builds the linearised problem of `calippso.lp` for the current configuration,
solves it, moves the particles by s* and inflates every diameter by √Γ*. The bound on the
displacements adapts to the previous step (`next_step_bound`): it grows when a stable
particle was held back by it and shrinks with the displacements as the packing converges,
which keeps the LP small and never lets the bound stall the approach to jamming.

At the end, contacts and forces come from the duals of an LP solved at the final positions
(a clean-up LP with rattlers frozen, when the duals of the last step do not balance to
`balance_tolerance` at the updated positions).
"""

from __future__ import annotations

import hashlib
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from .checkpoint import load_state, save_state, signature
from .contacts import (contact_mask, force_balance, isostaticity_gap, polish_forces,
                       positive_self_stress, remove_rattlers)
from .errors import JammingError, SolverError
from .lp import LinearProgram, build_lp, largest_safe_step, select_pairs
from .neighbors import SAME_PLACE, NeighborSearch, Pairs, check_no_duplicates
from .network_first import SettledNetwork, settle_candidate
from .network_guess import Candidate, candidate_networks, check_network_hint
from .newton import Refinement, refine_isostatic
from .packing import Packing, wrap
from .precompress import precompress, precompress_checkpoint
from .rattlers import separate_rattlers
from .result import JammingResult, history_from_records
from .settings import JamSettings
from .solvers import Basis, LPSolution
from .solvers.policy import (COLD_RESOLVE, FIRST, LPAttempt, attempt_plan, prepare_backends,
                              solution_problem)

__all__ = ["jam", "initial_step_bound", "next_step_bound"]

#: Bound on displacements in the final clean-up LP (mean diameters); at a jammed state the
#: solution is ~0 and the bound is inactive.
CLEANUP_STEP = 1e-3
#: A pair outside the contact network may overlap by at most this relative gap at a Newton
#: solution (round-off); more means the network is not the jammed one.
NEWTON_OVERLAP_TOLERANCE = 1e-12
#: `_check_box_size` stops a run whose largest diameter reaches (1 − this) × half the box
#: side with no stable particle.
SMALL_BOX_MARGIN = 1e-3
#: Smallest first bound on displacements chosen by `initial_step_bound` (mean diameters).
INITIAL_STEP_FLOOR = 1e-3
#: An input whose median nearest-neighbour gap exceeds this (mean diameters) is loose: a run
#: that does not converge says that `precompress_pressure` is the remedy.
LOOSE_INPUT_GAP = 1e-3
#: The loop stops as stalled (not converged) after this many LPs without progress.
STALL_LPS = 25
#: Candidate networks the network-first stage settles at most (each costs a few sparse
#: factorisations).
MAX_NETWORK_GUESSES = 3
#: Pairs closer than this relative gap count as touching when the LP duals are degenerate
#: (`_Jammer._hyperstatic_network`).
GEOMETRIC_CONTACT_GAP = 1e-11
#: A displacement at the bound limits Γ when its reduced cost |(Aᵀμ)_k| exceeds this fraction
#: of the largest dual (far above the solver's dual feasibility tolerance, far below the
#: reduced cost of a particle that the bound really holds back).
BINDING_REDUCED_COST = 1e-6


def jam(packing, diameters=None, box=None, *, solver: str = "highs", tol_gamma: float = 1e-12,
        tol_s: float = 1e-9, max_iters: int = 1000, verbose: bool = False,
        callback: Callable[[dict], bool | None] | None = None,
        checkpoint: str | os.PathLike | None = None, network=None,
        on_lp: Callable[[LPAttempt], None] | None = None, **options) -> JammingResult:
    """Bring a configuration of hard (hyper)spheres to its jamming point with CALiPPSO.

    Parameters
    ----------
    packing : Packing or array_like, shape (N, d)
        The configuration, or its positions (then pass `diameters` and `box` too).
    diameters : array_like, shape (N,), optional
        Diameters, when `packing` is an array of positions.
    box : array_like, shape (d,) or float, optional
        Box side lengths, when `packing` is an array of positions.
    solver : {"highs", "clarabel", "cvxpy"} or str
        LP backend. "highs" (interior point + crossover) gives vertex solutions whose duals
        identify contacts exactly; the others are interior-point solvers at tight tolerances.
        A backend added with `calippso.solvers.register_backend` is accepted by its name.
    tol_gamma : float
        Converged when √Γ − 1 < tol_gamma ...
    tol_s : float
        ... and max |s_iμ| over non-rattlers < tol_s, in units of the mean diameter.
    max_iters : int
        Largest number of LPs in the main loop.
    verbose : bool
        Print one line per LP.
    callback : callable, optional
        Called after every history record (every LP, and the "guess" and "newton" stages) with
        a dict (the record plus "iteration", the LPs solved so far, and "packing"); returning
        True stops the run after an LP or a Newton stage of the loop (the result then has
        ``converged=False``).
    checkpoint : str or PathLike, optional
        File (``.npz``) where the loop's state is saved atomically after every LP. If it
        exists, the run resumes from it (same input and settings required, otherwise
        ValueError) and gives the result the uninterrupted run would have given.
    network : array_like, shape (M, 2), int, optional
        A contact network the caller knows (e.g. `GenerationResult.contacts` of a
        soft-sphere quench): pairs of particle indices. It is tried first by the
        network-first stage (``network_first``) and used only if the Newton certificate
        proves its jamming point.
    on_lp : callable, optional
        Called after every backend call of the run (each LP, its retries and fallbacks, the
        cold re-solves and the force clean-up LP) with a `calippso.solvers.LPAttempt`: the LP
        number, the role of the call, the backend's name, the `LinearProgram`, the basis
        offered as warm start, the `LPSolution` (None if the backend failed) and why the loop
        refused it (None if accepted). Its return value is ignored; an exception it raises
        ends the run and reaches the caller unchanged. For benchmarks and diagnostics.
    **options
        Further `JamSettings` fields (e.g. ``network_first``, ``initial_step``,
        ``max_step``, ``contact_threshold``, ``feasibility_tolerance``). ``precompress_pressure=1e5``
        first compresses a loose input by Lubachevsky–Stillinger MD (`calippso.precompress`);
        with a checkpoint, that stage keeps its own file beside it (``*.precompress.npz``).

    Returns
    -------
    JammingResult

    Raises
    ------
    ValueError
        Bad input: wrong shapes, NaN, non-positive sizes, a particle wider than half the box,
        overlapping particles (beyond round-off, `overlap_tolerance`), too few particles to
        jam (fewer than 2 d + 1), a malformed ``network``, or a backend that is not
        registered (``solver``, ``fallback_solvers``) or cannot run here.
    JammingError
        Every backend failed on an LP (the exception keeps the last valid configuration),
        or ``network_first="require"`` and no guessed network was certified.
    """
    settings = JamSettings.from_options(solver=solver, tol_gamma=tol_gamma, tol_s=tol_s,
                                        max_iters=max_iters, verbose=verbose, **options)
    start = time.perf_counter()
    packing = _as_packing(packing, diameters, box)
    check_enough_particles(packing.n, packing.d)
    hint = None if network is None else check_network_hint(network, packing.n)
    notes = []
    if settings.precompress_pressure is not None:
        scale = packing.mean_diameter
        check_input_overlaps(NeighborSearch(wrap(packing.positions / scale, packing.box / scale),
                                            packing.diameters / scale, packing.box / scale),
                             settings.overlap_tolerance)
        packing, note = precompress(packing, settings.precompress_pressure,
                                    precompress_checkpoint(checkpoint))
        notes.append(note)
    return _Jammer(packing, settings, callback, checkpoint, start=start, notes=notes,
                   hint=hint, on_lp=on_lp).run()


def _as_packing(packing, diameters, box) -> Packing:
    if isinstance(packing, Packing):
        if diameters is not None or box is not None:
            raise TypeError("pass either a Packing, or positions with diameters and box")
        return packing
    if diameters is None or box is None:
        raise TypeError("jam(positions, diameters, box): diameters and box are required")
    return Packing(packing, diameters, box)


def check_enough_particles(n: int, d: int) -> None:
    """Raise ValueError when N particles cannot jam in d dimensions.

    Under the minimum-image convention a stable particle touches d + 1 distinct others, and an
    isostatic network of N_s particles has N_c = d (N_s − 1) + 1 ≤ N_s (N_s − 1) / 2 contacts:
    so N_s ≥ 2 d + 1, whatever the box.
    """
    least = 2 * d + 1
    if n < least:
        raise ValueError(f"cannot jam {n} particle(s) in d = {d}: a jammed packing in a "
                         f"periodic box needs at least 2 d + 1 = {least} particles (each stable "
                         f"particle touches d + 1 others, and an isostatic network of N_s "
                         f"particles has d (N_s - 1) + 1 contacts)")


def check_input_overlaps(search: NeighborSearch, tolerance: float) -> None:
    """Raise ValueError naming duplicated or overlapping particles of an input (in mean
    diameters, the loop's units).

    Overlaps down to a relative gap h = |r|/σ − 1 > −`tolerance` are round-off and accepted.
    """
    check_no_duplicates(search.positions, search.box, SAME_PLACE)
    close = search.pairs_within(float(search.diameters.max()))
    gaps = close.gaps
    if gaps.size and gaps.min() < -tolerance:
        k = int(np.argmin(gaps))
        count = int(np.count_nonzero(gaps < -tolerance))
        raise ValueError(
            f"overlapping particles in the input: {count} pair(s) overlap beyond round-off "
            f"(h < -{tolerance:g}), the worst is ({close.i[k]}, {close.j[k]}) with gap "
            f"h = |r|/sigma - 1 = {gaps[k]:.3e}; shrink every diameter by the factor 1 + h "
            f"of the worst pair, or make the start with a generator")


def initial_step_bound(gap: float, settings: JamSettings) -> float:
    """First bound on displacements: the median nearest-neighbour surface gap, at least
    `INITIAL_STEP_FLOOR`, clipped to [min_step, max_step].

    From a compressed state (LS at p ≥ 1e5, gaps ~1e-6) the particles still travel ~1e-3–1e-2
    to the jamming point; starting at the gap would spend several LPs growing the bound.

    Parameters
    ----------
    gap : float
        `median_gap` of the input configuration (mean diameters).
    settings : JamSettings
        `initial_step` overrides the rule; the result lies in [min_step, max_step].
    """
    step = settings.initial_step if settings.initial_step is not None else max(
        gap, INITIAL_STEP_FLOOR)
    return float(np.clip(step, settings.min_step, settings.max_step))


def median_gap(search: NeighborSearch) -> float:
    """Median over particles of the surface gap |r_ij| − σ_ij to the nearest neighbour
    (mean diameters): ~1e-6 for an LS state at reduced pressure 1e5, ~1e-2 for a
    force-biased start at φ ≈ 0.6."""
    distances, neighbours = search.nearest_neighbours()
    sigma = 0.5 * (search.diameters + search.diameters[neighbours])
    return float(np.median(distances - sigma))


def _at_bound(displacement, bound: float):
    """Whether a displacement (float or array) equals the bound, up to the solver's round-off."""
    return displacement >= bound * (1.0 - 1e-6)


def next_step_bound(step: float, taken: "_Step", settings: JamSettings) -> float:
    """Adapt the displacement bound to the step just taken.

    - A stable particle held at the bound means the bound limited the step: multiply it by
      `step_growth`.
    - Far from jamming (fewer than half the particles stable) the contact network is a set of
      small clusters that all count as rattlers; if any particle with a contact sat at the
      bound, grow the bound too, otherwise keep it.
    - Otherwise the next bound is `step_margin` × the largest displacement of a stable
      particle, so that it follows the shrinking steps of the final approach (and the LP
      keeps fewer rows), but it does not shrink while it limits Γ (`_Step.held_by_bound`):
      particles with d or fewer contacts count as rattlers, yet their neighbours can press
      them against the bound. Shrinking the bound with the stable particles' steps then
      stalled the loop at the smallest bound.
    """
    sparse_network = taken.stable_fraction < 0.5
    if (_at_bound(taken.max_displacement, step)
            or (sparse_network and _at_bound(taken.max_contacting, step))):
        proposed = step * settings.step_growth
    elif sparse_network:
        proposed = step
    elif taken.held_by_bound:
        proposed = max(step, settings.step_margin * taken.max_displacement)
    else:
        proposed = settings.step_margin * taken.max_displacement
    return float(np.clip(proposed, settings.min_step, settings.max_step))


@dataclass(eq=False)
class _Step:
    """One solved LP and what its duals say."""

    lp: LinearProgram
    solution: LPSolution
    contact_rows: np.ndarray       # rows that are contacts between stable particles
    rattlers: np.ndarray           # (N,) bool
    forces: np.ndarray             # (len(contact_rows),) f = μ/2, not normalised
    balance: float                 # at the LP's own geometry
    max_displacement: float        # over non-rattlers, mean diameters
    max_contacting: float          # over particles with at least one contact (before removal)
    stable_fraction: float         # fraction of particles that are not rattlers
    held_by_bound: bool            # relaxing the bound would increase Γ
    offered_warm_start: bool = False   # the LP was given the previous LP's basis

    @property
    def displacements(self) -> np.ndarray:
        return self.solution.x[:-1].reshape(self.lp.n, self.lp.d)

    @property
    def n_contacts(self) -> int:
        return int(self.contact_rows.shape[0])

    @property
    def hypostatic(self) -> bool:
        """Fewer contacts than d (N_s − 1) + 1, or no stable particle at all."""
        n_stable = int(self.rattlers.size - self.rattlers.sum())
        return n_stable == 0 or isostaticity_gap(self.n_contacts, n_stable, self.lp.d) < 0

    @property
    def needs_cold_resolve(self) -> bool:
        """A warm-started vertex with a hypostatic network, not held back by the bound.

        Such a vertex is solved again from scratch (`_Jammer._cold_resolve`): at a degenerate
        optimum the simplex can stop at a vertex whose duals leave contacts out. When the
        bound holds a particle back (`held_by_bound`), the bound stands in for the missing
        contact instead, and the cold solve ends with the same deficit: so it was in all five
        such re-solves measured (N = 1024 and 2048 in d = 3, N = 1024 in d = 4), 0.8–7 s each.
        """
        return self.solution.warm_started and self.hypostatic and not self.held_by_bound

    @property
    def normalization(self) -> float:
        return float(self.solution.duals @ self.lp.gamma_coefficients)

    def network(self) -> "_Network":
        pairs, rows = self.lp.pairs, self.contact_rows
        return _Network(pairs.i[rows], pairs.j[rows], self.forces, self.rattlers,
                        self.normalization, self.solution.solver, from_lp=True)


@dataclass(eq=False)
class _Network:
    """Contacts between stable particles and their forces f = μ/2 (LP normalisation)."""

    i: np.ndarray
    j: np.ndarray
    forces: np.ndarray
    rattlers: np.ndarray
    normalization: float
    solver: str
    from_lp: bool


def _network_key(i: np.ndarray, j: np.ndarray, n: int) -> str:
    """A digest of a contact network (its sorted pair keys i N + j), for `failed_networks`."""
    return hashlib.sha256(np.sort(i * n + j).tobytes()).hexdigest()


def _held_by_bound(lp: LinearProgram, solution: LPSolution) -> bool:
    """Whether the bound on the displacements limited Γ in this LP.

    At the optimum, a displacement s_k strictly inside its bound has a zero reduced cost
    (Aᵀμ)_k: the forces on that particle balance along k. A non-zero one at the bound is the
    bound's own multiplier, the rate at which Γ would grow if the bound were relaxed.
    """
    if solution.duals.size == 0:
        return False
    largest = float(solution.duals.max())
    if largest <= 0:
        return False
    s = solution.x[:-1]
    free = lp.col_upper[:-1] > 0
    at_bound = free & _at_bound(np.abs(s), lp.step_bound)
    if not at_bound.any():
        return False
    reduced = (lp.matrix.T @ solution.duals)[:-1]
    return bool(np.any(np.abs(reduced[at_bound]) > BINDING_REDUCED_COST * largest))


class _Jammer:
    """State of one `jam` call (internal units: mean input diameter = 1)."""

    def __init__(self, packing: Packing, settings: JamSettings, callback,
                 checkpoint: str | os.PathLike | None = None, start: float | None = None,
                 notes: list[str] | None = None, hint: np.ndarray | None = None,
                 on_lp: Callable[[LPAttempt], None] | None = None):
        self.settings = settings
        self.on_lp = on_lp
        self.hint = hint
        self.callback = callback
        self.start = time.perf_counter() if start is None else start
        self.scale = packing.mean_diameter
        self.n, self.d = packing.n, packing.d
        self.box = packing.box / self.scale
        self.positions = wrap(packing.positions / self.scale, self.box)
        self.diameters = packing.diameters / self.scale
        self.fixed = np.zeros(self.n, dtype=bool)
        if settings.pin:
            self.fixed[0] = True
        self.records: list[dict] = []
        self.notes: list[str] = list(notes or [])
        self.backends = prepare_backends(settings)
        self.failed_networks: set[str] = set()
        self.newton_failure = ""          # why the last Newton stage was not certified
        self.discarded_seconds = 0.0      # solver time of attempts whose LP was not taken
        self.retried_lps = 0
        self.stalled = False
        self.forced = np.zeros((0, 2), dtype=np.int64)
        self.basis: Basis | None = None   # warm start of the next LP
        self.search = NeighborSearch(self.positions, self.diameters, self.box)
        check_input_overlaps(self.search, settings.overlap_tolerance)
        self.input_median_gap = median_gap(self.search)
        self.step = initial_step_bound(self.input_median_gap, settings)
        self.checkpoint = None if checkpoint is None else Path(checkpoint)
        if self.checkpoint is not None:
            self.checkpoint_key = signature(packing, settings)
            self._resume(load_state(self.checkpoint, self.checkpoint_key))

    def _resume(self, state: dict | None) -> None:
        """Continue from a saved state (see `calippso.checkpoint`)."""
        if state is None:
            return
        self.positions, self.diameters = state["positions"], state["diameters"]
        self.search = NeighborSearch(self.positions, self.diameters, self.box)
        self.step, self.forced = state["step"], state["forced"]
        self.failed_networks, self.records = state["failed_networks"], state["records"]
        self.notes, self.basis = state["notes"], state["basis"]
        if self.records:
            self.start -= self.records[-1]["wall_time"]

    def _save_state(self) -> None:
        if self.checkpoint is not None:
            save_state(self.checkpoint, self.checkpoint_key, {
                "positions": self.positions, "diameters": self.diameters, "step": self.step,
                "forced": self.forced, "failed_networks": self.failed_networks,
                "records": self.records, "notes": self.notes, "basis": self.basis})

    # ----------------------------------------------------------------- helpers
    @property
    def lps_solved(self) -> int:
        """LPs solved so far (history records of the LP loop and the force clean-up)."""
        return sum(record["stage"] in ("lp", "cleanup") for record in self.records)

    def packing(self) -> Packing:
        """The current configuration in the caller's units."""
        return Packing(self.positions * self.scale, self.diameters * self.scale,
                       self.box * self.scale)

    def _fail(self, message: str) -> JammingError:
        return JammingError(message, packing=self.packing(),
                            history=history_from_records(self.records))

    def _pairs(self, search: NeighborSearch, step: float, stable: np.ndarray | None,
               forced: np.ndarray) -> Pairs:
        pairs = select_pairs(search, step)
        if forced.shape[0]:
            keys = pairs.i * self.n + pairs.j
            extra = forced[~np.isin(forced[:, 0] * self.n + forced[:, 1], keys)]
            if extra.shape[0]:
                more = search.pairs_of(extra[:, 0], extra[:, 1])
                pairs = Pairs(*(np.concatenate([a, b]) for a, b in zip(
                    (pairs.i, pairs.j, pairs.vectors, pairs.distances, pairs.sigma),
                    (more.i, more.j, more.vectors, more.distances, more.sigma))))
        if stable is not None:
            pairs = pairs.subset(stable[pairs.i] & stable[pairs.j])
        return pairs

    def _solve(self, search: NeighborSearch, step: float, fixed: np.ndarray,
               stable: np.ndarray | None = None,
               forced: np.ndarray = np.zeros((0, 2), dtype=np.int64)) -> _Step:
        """Build and solve one LP; on failure retry with a smaller bound, then other backends
        (`calippso.solvers.policy.attempt_plan`)."""
        failures = []
        warm_start = self.basis if self.settings.warm_start else None
        for attempt in attempt_plan(self.settings.solver, self.settings.fallback_solvers, step):
            bound = attempt.bound
            lp = build_lp(self._pairs(search, bound, stable, forced), self.n, self.d, bound, fixed)
            solution, failure = self._call_backend(attempt.backend, lp, warm_start, attempt.role)
            if failure is None:
                if attempt.role != FIRST:
                    if not self.retried_lps:
                        self.notes.append(f"LP {self.lps_solved + 1} needed a retry "
                                          f"({attempt.backend}, bound {bound:.1e}) after: "
                                          f"{'; '.join(failures)}")
                    self.retried_lps += 1
                taken = self._analyse(lp, solution, stable)
                if taken.needs_cold_resolve:
                    taken = self._cold_resolve(attempt.backend, lp, taken, stable)
                taken.offered_warm_start = warm_start is not None
                return taken
            failures.append(f"{attempt.backend} (bound {bound:.1e}): {failure}")
            warm_start = None   # retries start from scratch
        raise self._fail(f"every LP backend failed at LP {self.lps_solved + 1}: "
                         + "; ".join(failures))

    def _call_backend(self, name: str, lp: LinearProgram, warm_start: Basis | None,
                      role: str) -> tuple[LPSolution | None, str | None]:
        """One backend call: its solution and None, or what failed (the backend's
        `SolverError`, or the check its solution failed).

        Only `SolverError` is caught: any other exception is a bug and ends the run. The time
        of a refused call is added to the next history record; ``on_lp`` sees every call.
        """
        began = time.perf_counter()
        try:
            solution = self.backends[name].solve(lp, warm_start)
        except SolverError as error:
            solution, failure = None, f"{type(error).__name__}: {error}"
            self.discarded_seconds += time.perf_counter() - began
        else:
            failure = solution_problem(lp, solution)
            if failure is not None:
                self.discarded_seconds += solution.seconds
        if self.on_lp is not None:
            self.on_lp(LPAttempt(self.lps_solved + 1, role, name, lp, warm_start, solution,
                                 failure))
        return solution, failure

    def _cold_resolve(self, name: str, lp: LinearProgram, taken: _Step,
                      stable: np.ndarray | None) -> _Step:
        """The same LP solved from scratch, when a warm-started vertex gave a hypostatic network.

        At a degenerate optimum (crystalline patches, nearly redundant contacts) the simplex
        from an old basis can end at a vertex whose duals leave out contacts; interior point +
        crossover ends near the centre of the optimal face and keeps them. Keeps the warm
        solution if the cold one fails. Called only when `_Step.needs_cold_resolve`.
        """
        cold, failure = self._call_backend(name, lp, None, COLD_RESOLVE)
        if failure is not None:
            return taken
        return self._analyse(lp, replace(cold, seconds=cold.seconds + taken.solution.seconds),
                             stable)

    def _analyse(self, lp: LinearProgram, solution: LPSolution,
                 stable: np.ndarray | None) -> _Step:
        threshold = (self.settings.contact_threshold if solution.vertex
                     else self.settings.interior_contact_threshold)
        rows = np.flatnonzero(contact_mask(solution.duals, threshold))
        pairs = lp.pairs
        contacting = np.zeros(self.n, dtype=bool)
        contacting[pairs.i[rows]] = contacting[pairs.j[rows]] = True
        rattlers, kept = remove_rattlers(self.n, self.d, pairs.i[rows], pairs.j[rows])
        if stable is not None:
            rattlers |= ~stable
        rows = rows[kept]
        forces = 0.5 * solution.duals[rows]
        normals = pairs.vectors[rows] / pairs.distances[rows, None]
        balance = force_balance(self.n, pairs.i[rows], pairs.j[rows], normals, forces, ~rattlers)
        s = solution.x[:-1].reshape(self.n, self.d)
        free = lp.col_upper[:-1].reshape(self.n, self.d)[:, 0] > 0
        max_contacting = float(np.abs(s[contacting & free]).max(initial=0.0))
        # with no stable particle at all, the steps of particles with a contact count: a run
        # is not converged just because rattler removal emptied its network
        max_displacement = (float(np.abs(s[~rattlers & free]).max(initial=0.0))
                            if (~rattlers).any() else max_contacting)
        return _Step(lp, solution, rows, rattlers, forces, balance, max_displacement,
                     max_contacting, float(np.count_nonzero(~rattlers)) / self.n,
                     _held_by_bound(lp, solution))

    def _record(self, step: _Step, min_gap: float, stage: str = "lp") -> dict:
        record = {
            "stage": stage,
            "wall_time": time.perf_counter() - self.start,
            "solver_time": step.solution.seconds + self.discarded_seconds,
            "sqrt_gamma_minus_1": float(np.sqrt(1.0 + step.solution.gamma) - 1.0),
            "max_displacement": step.max_displacement,
            "rows": step.lp.n_rows,
            "step_bound": step.lp.step_bound,
            "n_contacts": step.n_contacts,
            "isostaticity_gap": isostaticity_gap(step.n_contacts,
                                                 int(self.n - step.rattlers.sum()), self.d),
            "force_balance": step.balance,
            "min_gap": min_gap,
            "phi": self.packing().phi,
        }
        self.records.append(record)
        self.discarded_seconds = 0.0
        if self.settings.verbose:
            self._print(record)
        return record

    def _print(self, record: dict) -> None:
        if len(self.records) == 1:
            print(f"{'#':>4} {'stage':>7} {'rows':>8} {'sqrtG-1':>9} {'max|s|':>9} {'bound':>8} {'Nc':>7} "
                  f"{'iso':>5} {'balance':>8} {'min gap':>9} {'phi':>12} {'LP s':>7} {'total s':>8}")
        print(f"{len(self.records):4d} {record['stage']:>7} {record['rows']:8d} "
              f"{record['sqrt_gamma_minus_1']:9.2e} "
              f"{record['max_displacement']:9.2e} {record['step_bound']:8.1e} "
              f"{record['n_contacts']:7d} {record['isostaticity_gap']:5d} "
              f"{record['force_balance']:8.1e} {record['min_gap']:9.2e} {record['phi']:12.9f} "
              f"{record['solver_time']:7.2f} {record['wall_time']:8.2f}", flush=True)

    # ----------------------------------------------------------------- main loop
    def run(self) -> JammingResult:
        settings = self.settings
        converged = False
        stopped = False
        network: _Network | None = None
        verifying = False
        if settings.network_first != "off" and not self.records:
            network = self._network_first()
            if network is not None:
                return self._finish(network, converged=True, stopped=False)
            if settings.network_first == "require":
                raise self._fail("network_first='require': no network guessed from the input "
                                 "was certified (" + self.notes[-1] + ")")
        while self.lps_solved < settings.max_iters:
            bound = largest_safe_step(self.search, self.step)
            if bound < settings.min_step * 1e-3:
                raise self._fail("box too small: even a vanishing step would need pairs "
                                 "beyond half the box side")
            step_result = self._solve(self.search, bound, self.fixed, forced=self.forced)
            s, gamma = step_result.displacements, step_result.solution.gamma
            positions = wrap(self.positions + s, self.box)
            diameters = self.diameters * np.sqrt(1.0 + gamma)
            search = NeighborSearch(positions, diameters, self.box)
            close = search.pairs_within(float(diameters.max()) * (1.0 + 1e-6))
            overlapping = close.gaps < 0
            keys = step_result.lp.pairs.i * self.n + step_result.lp.pairs.j
            outside = overlapping & ~np.isin(close.i * self.n + close.j, keys)
            if outside.any():
                # A pair left out of the LP overlaps (round-off at the edge of the safe
                # selection): keep it from now on and solve this LP again.
                new = np.column_stack([close.i[outside], close.j[outside]])
                self.forced = np.unique(np.concatenate([self.forced, new]), axis=0)
                self.notes.append(f"{int(outside.sum())} pair(s) outside the LP overlapped "
                                  f"after LP {self.lps_solved + 1}; re-solved with them")
                self.discarded_seconds += step_result.solution.seconds
                continue
            self.positions, self.diameters, self.search = positions, diameters, search
            min_gap = float(close.gaps.min()) if len(close) else float("inf")
            record = self._record(step_result, min_gap)
            network = step_result.network()
            converged = (record["sqrt_gamma_minus_1"] < settings.tol_gamma
                         and step_result.max_displacement < settings.tol_s
                         and step_result.max_displacement < 0.5 * bound
                         and not step_result.held_by_bound)
            if verifying:
                verifying = False
                if converged:
                    self.notes.append("an LP at the Newton solution confirmed convergence")
                else:
                    self.notes.append("the LP at the Newton solution did not confirm "
                                      "convergence; the loop went on")
            if self._stop_requested(record):
                stopped, converged = True, False
                break
            self._check_box_size(step_result)
            if converged:
                break
            if self._stalled():
                self.stalled = True
                break
            # adapt from the bound the accepted LP had (a retry may have used a smaller one)
            self.step = next_step_bound(step_result.lp.step_bound, step_result, settings)
            self.basis = self._warm_start_basis(step_result)
            if (settings.newton and record["isostaticity_gap"] == 0 and record["n_contacts"]
                    and step_result.max_displacement < settings.newton_start):
                refined = self._newton(network)
                if refined is not None:
                    network = refined
                    if self._stop_requested(self.records[-1]):
                        stopped = True
                        break
                    if not settings.verify_newton:
                        converged = True
                        break
                    verifying, self.step = True, CLEANUP_STEP
            self._save_state()
        if network is None:
            raise self._fail(f"no LP was solved (max_iters = {settings.max_iters})")
        return self._finish(network, converged, stopped)

    def _warm_start_basis(self, taken: _Step) -> Basis | None:
        """The basis the next LP starts from, or None for a cold start.

        A warm start pays off when consecutive LPs differ little. It does not when a stable
        particle moved by half the bound or more (the particles still travel far, so the next
        optimal basis is far from this one), nor right after a warm start that failed
        (the next LP is then solved cold, and the one after tries again).
        """
        warm_failed = taken.offered_warm_start and not taken.solution.warm_started
        if warm_failed or taken.max_displacement >= 0.5 * taken.lp.step_bound:
            return None
        return taken.solution.basis

    def _check_box_size(self, taken: _Step) -> None:
        """Stop with an error when the particles grow to half the box side without jamming.

        Pairs are taken at their minimum image, which describes the packing only while every
        contact distance stays below half the box side. A small periodic box (few particles,
        high d) can leave every particle a rattler until the diameters approach that limit;
        the loop would then creep towards it with ever smaller steps.
        """
        half = 0.5 * float(self.box.min())
        largest = float(self.diameters.max())
        if taken.stable_fraction == 0 and largest >= (1.0 - SMALL_BOX_MARGIN) * half:
            raise self._fail(
                f"box too small: the largest diameter has grown to {largest / half:.4f} x half "
                f"the box side after {self.lps_solved} LPs with no stable particle; the "
                f"packing cannot jam under the minimum-image convention in this box (use more "
                f"particles or a larger box)")

    def _stalled(self) -> bool:
        """The last `STALL_LPS` LPs gained nothing in Γ and did not shrink the displacements."""
        lps = [r for r in self.records if r["stage"] == "lp"][-STALL_LPS:]
        if len(lps) < STALL_LPS:
            return False
        gains = [r["sqrt_gamma_minus_1"] for r in lps]
        steps = [r["max_displacement"] for r in lps]
        return (max(gains) < self.settings.tol_gamma
                and min(steps[-5:]) >= 0.5 * min(steps[:5]))

    def _stop_requested(self, record: dict) -> bool:
        return self.callback is not None and bool(self.callback(
            {**record, "iteration": self.lps_solved, "packing": self.packing()}))

    # ----------------------------------------------------------------- network first
    def _network_first(self) -> _Network | None:
        """The input's own contact network, certified by the Newton stage with no LP, or None.

        Candidates come from `calippso.network_guess` (the hint first, then the gap
        spectrum); at most `MAX_NETWORK_GUESSES` are settled by `calippso.network_first`
        (restricted LP and Newton, a few rounds) and certified by the Newton stage. Each
        adds a history record (stage "guess"), a certified one also the Newton record; the
        status notes say what happened.
        """
        start = time.perf_counter()
        candidates = candidate_networks(self.search, self.d, self.hint)[:MAX_NETWORK_GUESSES]
        if not candidates:
            self.notes.append("network first: the input holds no isostatic contact network "
                              "(not near a jamming point), so the LP loop ran")
            return None
        failures = []
        for candidate in candidates:
            settled, failure = settle_candidate(self.search, candidate, self.d)
            self._record_guess(candidate, settled, time.perf_counter() - start)
            if settled is not None:
                network = _Network(settled.i, settled.j, np.zeros(settled.i.shape[0]),
                                   settled.rattlers, float("nan"), "none", from_lp=False)
                origin = (f"{'given as a hint' if candidate.source == 'hint' else 'read from the gap spectrum'}"
                          f", {settled.i.shape[0]} contacts"
                          + (f", {settled.opened} near pair(s) left open" if settled.opened else "")
                          + (f", settled in {settled.rounds} rounds" if settled.rounds > 1 else ""))
                refined = self._newton(network, origin=origin, refined=settled.refinement)
                if refined is not None:
                    if self.callback is not None:
                        self.callback({**self.records[-1], "iteration": 0,
                                       "packing": self.packing()})
                    return refined
                failure = self.newton_failure
                # refused here, from the input's positions: the LP loop may still reach this
                # network, and its Newton stage must not skip it as tried before
                self.failed_networks.discard(_network_key(settled.i, settled.j, self.n))
            failures.append(f"{candidate.source}: {failure}")
            start = time.perf_counter()
        self.notes.append(f"network first: no guessed network was certified "
                          f"({'; '.join(failures)}), so the LP loop ran")
        return None

    def _record_guess(self, candidate: Candidate, settled: SettledNetwork | None,
                      seconds: float) -> None:
        """History record of one candidate network (stage "guess"; no LP, nothing moves):
        the contacts and isostaticity gap of the settled network, or of the candidate's
        pairs when it did not settle."""
        close = self.search.pairs_within(float(self.diameters.max()) * (1.0 + 1e-6))
        if settled is not None:
            n_contacts, stable = int(settled.i.shape[0]), ~settled.rattlers
        else:
            rattlers, kept = remove_rattlers(self.n, self.d, candidate.pairs.i,
                                             candidate.pairs.j)
            n_contacts, stable = int(kept.sum()), ~rattlers
        self.records.append({
            "stage": "guess", "wall_time": time.perf_counter() - self.start,
            "solver_time": seconds, "sqrt_gamma_minus_1": 0.0, "max_displacement": 0.0,
            "rows": len(candidate.pairs), "step_bound": float("nan"),
            "n_contacts": n_contacts,
            "isostaticity_gap": isostaticity_gap(n_contacts, int(stable.sum()), self.d),
            "force_balance": float("nan"),
            "min_gap": float(close.gaps.min()) if len(close) else float("inf"),
            "phi": self.packing().phi,
        })
        if self.settings.verbose:
            self._print(self.records[-1])
        if self.callback is not None:
            self.callback({**self.records[-1], "iteration": 0, "packing": self.packing()})

    # ----------------------------------------------------------------- Newton stage
    def _newton(self, network: _Network, retry: bool = False, origin: str | None = None,
                refined: Refinement | None = None) -> _Network | None:
        """Solve the contact equations of an isostatic network; None unless certified.

        Certified means: every force positive and no other pair overlapping beyond
        `NEWTON_OVERLAP_TOLERANCE` (see `calippso.newton`). Rattlers that the moved cages
        now overlap are first moved out of the way (`calippso.rattlers.separate_rattlers`).
        A network that failed once is not tried again, unless `retry` (at the end of the
        loop, from the converged positions). `origin` describes a network that did not come
        from an LP (the network-first stage), for the status; `refined` is its Newton
        solution from the current positions when already computed (`calippso.network_first`).
        On success the configuration moves to the certified jamming point and a history
        record (stage "newton") is added; on failure `newton_failure` says why.
        """
        order = np.sort(network.i * self.n + network.j)
        key = _network_key(network.i, network.j, self.n)
        if key in self.failed_networks and not retry:
            self.newton_failure = "tried before"
            return None
        start = time.perf_counter()
        if refined is None:
            refined = refine_isostatic(self.positions, self.diameters, self.box, network.i,
                                       network.j, ~network.rattlers)
        if refined is None:
            self.failed_networks.add(key)
            self.newton_failure = "Newton did not converge or the Jacobian is singular"
            return None
        positions = refined.positions
        search, close, overlapping = self._overlaps_outside(positions, refined.diameters,
                                                            order)
        if refined.positive and overlapping.any() and np.all(
                network.rattlers[close.i[overlapping]] | network.rattlers[close.j[overlapping]]):
            # only rattlers overlap: the cage moved under a rattler that touched it
            separated = separate_rattlers(positions, refined.diameters, self.box,
                                          network.rattlers)
            if separated is not None:
                positions = separated
                search, close, overlapping = self._overlaps_outside(
                    positions, refined.diameters, order)
        touching = 0
        if origin is not None:
            # a guessed network must be the whole contact network: another touching pair of
            # stable particles means a degenerate (hyperstatic) packing, left to the LPs
            stable = ~network.rattlers
            outside = ~np.isin(close.i * self.n + close.j, order)
            touching = int(np.count_nonzero(outside & (close.gaps < GEOMETRIC_CONTACT_GAP)
                                            & stable[close.i] & stable[close.j]))
        if overlapping.any() or not refined.positive or touching:
            self.failed_networks.add(key)
            self.newton_failure = (
                "a non-positive force" if not refined.positive else
                f"{int(overlapping.sum())} other pair(s) would overlap" if overlapping.any()
                else f"{touching} other pair(s) touch (a hyperstatic packing)")
            return None
        self.positions, self.diameters, self.search = (positions, refined.diameters, search)
        current = search.pairs_of(network.i, network.j)
        balance = force_balance(self.n, current.i, current.j,
                                current.vectors / current.distances[:, None], refined.forces,
                                ~network.rattlers)
        weights = current.sigma**2 / current.distances
        n_stable = int(self.n - network.rattlers.sum())
        self.records.append({
            "stage": "newton",
            "wall_time": time.perf_counter() - self.start,
            "solver_time": time.perf_counter() - start,
            "sqrt_gamma_minus_1": refined.sqrt_gamma_minus_1,
            "max_displacement": refined.max_displacement,
            "rows": int(network.i.shape[0]),
            "step_bound": float("nan"),
            "n_contacts": int(network.i.shape[0]),
            "isostaticity_gap": isostaticity_gap(int(network.i.shape[0]), n_stable, self.d),
            "force_balance": balance,
            "min_gap": float(close.gaps.min()) if len(close) else float("inf"),
            "phi": self.packing().phi,
        })
        if self.settings.verbose:
            self._print(self.records[-1])
        solved = (f"by Newton ({refined.iterations} iterations, {refined.factorizations} "
                  f"factorisation(s), residual {refined.residual:.0e})")
        if origin is None:
            self.notes.append(f"contact equations solved {solved} after {self.lps_solved} "
                              f"LPs; certified by positive forces and no overlap")
        else:
            self.notes.append(f"the input's own contact network ({origin}) solved {solved} "
                              f"with no LP; certified by positive forces and no overlap")
        return _Network(network.i, network.j, refined.forces, network.rattlers,
                        float(refined.forces @ weights), network.solver, from_lp=False)

    def _overlaps_outside(self, positions: np.ndarray, diameters: np.ndarray,
                          contact_keys: np.ndarray) -> tuple[NeighborSearch, Pairs, np.ndarray]:
        """The neighbour search of a configuration, its close pairs, and which of those
        overlap beyond `NEWTON_OVERLAP_TOLERANCE` without being a contact (sorted keys
        i N + j)."""
        search = NeighborSearch(positions, diameters, self.box)
        close = search.pairs_within(float(diameters.max()) * (1.0 + 1e-6))
        is_contact = np.isin(close.i * self.n + close.j, contact_keys)
        return search, close, ~is_contact & (close.gaps < -NEWTON_OVERLAP_TOLERANCE)

    # ----------------------------------------------------------------- final forces
    def _finish(self, network: _Network, converged: bool, stopped: bool) -> JammingResult:
        settings = self.settings
        current = self.search.pairs_of(network.i, network.j)
        balance = force_balance(self.n, current.i, current.j,
                                current.vectors / current.distances[:, None], network.forces,
                                ~network.rattlers)
        if balance > settings.balance_tolerance and network.from_lp and converged:
            refined = self._newton(network, retry=True) if settings.newton else None
            if refined is not None:
                network, balance = refined, self.records[-1]["force_balance"]
        if (balance > settings.balance_tolerance and network.from_lp
                and not network.rattlers.all()):
            stable = ~network.rattlers
            fixed = network.rattlers.copy()
            if stable.any():
                fixed[np.flatnonzero(stable)[0]] = True
            cleanup = self._solve(self.search, CLEANUP_STEP, fixed, stable=stable)
            self._record(cleanup, self.records[-1]["min_gap"], stage="cleanup")
            network, balance = cleanup.network(), cleanup.balance
            if cleanup.max_displacement > 0.5 * CLEANUP_STEP:
                self.notes.append("the force clean-up LP found a floppy motion: the packing "
                                  "is not rigid")
        if converged:
            network, balance = self._hyperstatic_network(network, balance)
        forces = network.forces
        if balance > settings.balance_tolerance and forces.size:
            forces, balance = self._polished(network, balance)
        contacts = np.column_stack([network.i, network.j]).astype(np.int64)
        order = np.lexsort((contacts[:, 1], contacts[:, 0]))
        forces = forces[order]
        mean_force = forces.mean() if forces.size else 1.0
        self._remove_roundoff_overlaps()
        n_stable = int(self.n - network.rattlers.sum())
        self.n_stable_final = n_stable
        gap = isostaticity_gap(contacts.shape[0], n_stable, self.d)
        return JammingResult(
            packing=self.packing(), contacts=contacts[order], forces=forces / mean_force,
            rattlers=network.rattlers.copy(), converged=converged,
            status=self._status(converged, stopped, gap),
            iterations=self.lps_solved,
            history=history_from_records(self.records),
            wall_time=time.perf_counter() - self.start, force_balance=balance,
            dual_normalization=network.normalization, solver=network.solver)

    def _hyperstatic_network(self, network: _Network, balance: float) -> tuple[_Network, float]:
        """The touching pairs as the contact network, when the LP's duals missed contacts.

        At a degenerate jammed point (crystals, other hyperstatic packings) the LP has many
        optimal dual solutions, and a vertex solution may put its weight on a few rows only,
        leaving the others, and particles, looking like non-contacts and rattlers. When the LP
        network is hypostatic or has no stable particle, and the pairs that touch
        (h < `GEOMETRIC_CONTACT_GAP`) give a network with more stable particles (or as many,
        and more contacts), the touching network is used instead, with the positive
        self-stress near uniform forces that `positive_self_stress` finds, if there is one
        and it balances. Otherwise the LP network is kept.
        """
        n_stable_lp = int(self.n - network.rattlers.sum())
        lp_gap = isostaticity_gap(network.i.shape[0], n_stable_lp, self.d)
        if n_stable_lp > 0 and lp_gap >= 0:
            return network, balance
        close = self.search.pairs_within(float(self.diameters.max()) * (1.0 + 1e-6))
        touching = close.subset(close.gaps < GEOMETRIC_CONTACT_GAP)
        rattlers, kept = remove_rattlers(self.n, self.d, touching.i, touching.j)
        touching = touching.subset(kept)
        n_stable_touching = int(np.count_nonzero(~rattlers))
        if (n_stable_touching, len(touching)) <= (n_stable_lp, network.i.shape[0]):
            return network, balance
        normals = touching.vectors / touching.distances[:, None]
        weights = touching.sigma**2 / touching.distances
        forces = positive_self_stress(self.n, touching.i, touching.j, normals, weights)
        if forces is None:
            return network, balance
        new_balance = force_balance(self.n, touching.i, touching.j, normals, forces, ~rattlers)
        if new_balance > self.settings.balance_tolerance:
            return network, balance
        self.notes.append(f"contacts taken from the touching pairs (h < "
                          f"{GEOMETRIC_CONTACT_GAP:g}): the LP duals are degenerate here; "
                          f"forces are a positive self-stress near uniform")
        return _Network(touching.i, touching.j, forces, rattlers, float(forces @ weights),
                        network.solver, from_lp=False), new_balance

    def _polished(self, network: _Network, balance: float) -> tuple[np.ndarray, float]:
        """Forces refined by least squares on the equilibrium equations, if that helps."""
        geometry = self.search.pairs_of(network.i, network.j)
        normals = geometry.vectors / geometry.distances[:, None]
        weights = geometry.sigma**2 / geometry.distances
        polished = polish_forces(self.n, geometry.i, geometry.j, normals, weights,
                                 network.forces)
        new_balance = force_balance(self.n, geometry.i, geometry.j, normals, polished,
                                    ~network.rattlers)
        if np.all(polished > 0) and new_balance < balance:
            self.notes.append(f"forces polished by least squares (balance {balance:.1e} -> "
                              f"{new_balance:.1e})")
            return polished, new_balance
        return network.forces, balance

    def _remove_roundoff_overlaps(self) -> None:
        close = self.search.pairs_within(float(self.diameters.max()) * (1.0 + 1e-6))
        if not len(close):
            return
        worst = float(close.gaps.min())
        if worst < 0:
            factor = (1.0 + worst) * (1.0 - 4 * np.finfo(float).eps)
            self.diameters = self.diameters * factor
            self.search = NeighborSearch(self.positions, self.diameters, self.box)
            self.notes.append(f"diameters scaled by 1 - {1 - factor:.1e} to remove round-off "
                              f"overlaps (worst gap {worst:.1e})")
            after = self.search.pairs_within(float(self.diameters.max()) * (1.0 + 1e-6)).gaps
            self.records[-1]["min_gap"] = float(after.min()) if after.size else float("inf")

    def _status(self, converged: bool, stopped: bool, gap: int) -> str:
        # the loop's last step, not the force clean-up LP (whose step is never taken)
        last = [record for record in self.records if record["stage"] != "cleanup"][-1]
        if converged and self.lps_solved == 0:
            head = "Jammed: the input's own contact network certified, with no LP"
        elif converged:
            head = f"Jammed: converged after {self.lps_solved} LPs"
        elif stopped:
            head = f"Stopped by the callback after {self.lps_solved} LPs"
        elif self.stalled:
            head = (f"Stalled after {self.lps_solved} LPs: the last {STALL_LPS} gained nothing "
                    f"in Gamma and their displacements did not shrink")
        else:
            head = f"Not converged after {self.lps_solved} LPs (max_iters)"
        if not self.records or self.n_stable_final == 0:
            tail = "no stable particle (every particle is a rattler)"
        elif gap == 0:
            tail = "isostatic"
        else:
            tail = f"{'hyperstatic' if gap > 0 else 'hypostatic'} (isostaticity gap {gap:+d})"
        if last["stage"] == "newton":
            # the Newton stage's own move: the certificate, not the tolerances, ends the run
            last_step = (f"the Newton stage moved stable particles by up to "
                         f"{last['max_displacement']:.1e} and grew the diameters by "
                         f"sqrt(Gamma)-1 = {last['sqrt_gamma_minus_1']:.1e}")
        else:
            last_step = (f"sqrt(Gamma)-1 = {last['sqrt_gamma_minus_1']:.1e}, "
                         f"max|s| = {last['max_displacement']:.1e}")
        sentence = f"{head} ({last_step}); {tail}."
        notes = self.notes + ([f"{self.retried_lps} LPs in all needed a retry"]
                              if self.retried_lps > 1 else [])
        if not (converged or stopped) and self.input_median_gap > LOOSE_INPUT_GAP:
            notes.append(f"the input is loose (median nearest-neighbour gap "
                         f"{self.input_median_gap:.1e} mean diameters), where the LP loop "
                         f"alone can take hundreds of LPs: precompress_pressure=1e5 (CLI: "
                         f"--precompress 1e5) first compresses it by LS MD")
        if notes:
            sentence += " Notes: " + "; ".join(notes) + "."
        return sentence
