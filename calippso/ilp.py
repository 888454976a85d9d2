"""The CALiPPSO loop: iterate linear programs until the packing is jammed.

Each iteration builds the linearised problem of `calippso.lp` for the current configuration,
has it solved (`calippso.solvers.policy.SolverPolicy`: retries, fallbacks, warm starts),
moves the particles by s* and inflates every diameter by √Γ*. The bound on the
displacements adapts to the previous step (`next_step_bound`): it grows when a stable
particle was held back by it and shrinks with the displacements as the packing converges,
which keeps the LP small and never lets the bound stall the approach to jamming. The loop
stops when an LP meets the tolerances, or when the Newton stage certifies the jamming point
of an isostatic LP network (`calippso.network.certify_network`); `StopReason` says which.

Before any LP, the network-first stage tries to certify the input's own contact network. At
the end, the functions of `calippso.network` repair the forces where needed (a clean-up LP
with rattlers frozen, the touching pairs of a degenerate packing, least squares) and shrink
away round-off overlaps. Every stage adds a record to the run's `calippso.history.History`.

The input is checked by `calippso.inputs`; what an LP's answer says (contacts, rattlers,
forces, whether the bound held a particle back) is read by `calippso.step`.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict
from typing import Callable

import numpy as np

from .atomic import digest
from .checkpoint import Checkpoint
from .contacts import isostaticity_gap
from .errors import JammingError
from .history import HISTORY_COLUMNS, History, Record, StopReason, status_sentence
from .inputs import as_packing, check_enough_particles, check_input_overlaps
from .lp import build_lp, largest_safe_step, select_pairs, select_walls
from .neighbors import NeighborSearch, Pairs
from .network import (ContactNetwork, certify_network, network_balance, network_key,
                      polished_forces, remove_roundoff_overlaps, touching_network,
                      walls_near_contact)
from .network_first import SettledNetwork, settle_candidate
from .container_guess import container_candidates
from .network_guess import Candidate, candidate_networks, check_network_hint
from .newton import NEWTON_FAILED, Refinement, pinned_coordinates, refine_isostatic
from .packing import Packing, wrap
from .pivots import PivotPath, describe_path, pivot_to_jamming
from .rattlers import remove_rattlers
from .result import JammingResult
from .settings import JamSettings
from .solvers import Basis
from .solvers.policy import LPAttempt, LPFailed, SolverPolicy, next_warm_start
from .step import Step, analyse, at_bound
from .walls import WallRows, out_of_layer_moves, wall_ids, wall_rows_of

__all__ = ["jam", "initial_step_bound", "next_step_bound"]

#: Bound on displacements in the final clean-up LP (mean diameters); at a jammed state the
#: solution is ~0 and the bound is inactive.
CLEANUP_STEP = 1e-3
#: `_check_box_size` stops a run whose largest diameter reaches (1 − this) × half the box
#: side with no stable particle.
SMALL_BOX_MARGIN = 1e-3
#: Smallest first bound on displacements chosen by `initial_step_bound` (mean diameters).
INITIAL_STEP_FLOOR = 1e-3
#: An input whose median nearest-neighbour gap exceeds this (mean diameters) is loose: a run
#: that does not converge says that precompressing it (`calippso.protocols.precompress`) is
#: the remedy.
LOOSE_INPUT_GAP = 1e-3
#: A safe step bound below this fraction of `JamSettings.min_step` means that even a vanishing
#: step would need pairs beyond half the box side: the box is too small.
VANISHING_STEP_FRACTION = 1e-3
#: A step counts as converged only when its largest displacement stays below this fraction
#: of its bound (the bound did not hold it back).
INSIDE_BOUND_FRACTION = 0.5
#: Candidate networks the network-first stage settles at most (each costs a few sparse
#: factorisations).
MAX_NETWORK_GUESSES = 3
#: Largest move off a wall (mean diameters) after an LP that converged hypostatic between
#: walls, also the next LP's bound (`_Jammer._kick_off_walls`); how many times that is done.
WALL_KICK_STEP = 1e-3
MAX_WALL_KICKS = 20
#: ... done also when an LP between walls grows √Γ by less than this with a hypostatic
#: network: the LPs then creep along such a mode by second-order steps.
WALL_KICK_GROWTH = 1e-9
#: Pairs closer than this relative gap touch, and those with |n_μ| below the next value
#: lie in a layer parallel to the walls of axis μ (`calippso.walls.out_of_layer_moves`).
WALL_KICK_TOUCHING = 1e-6
WALL_KICK_COPLANAR = 1e-6
#: Settings that do not change the sequence of LPs, left out of a checkpoint's signature.
CHECKPOINT_FREE_SETTINGS = ("verbose", "max_iters")
#: No pairs: the LP's forced rows at the start.
NO_PAIRS = np.zeros((0, 2), dtype=np.int64)


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
        File (``.npz``, appended when missing) where the loop's state is saved atomically
        after every LP (`calippso.checkpoint.Checkpoint`). If it exists, the run resumes from
        it (same input and settings required, otherwise ValueError naming what differs) and
        gives the result the uninterrupted run would have given.
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
        ``max_step``, ``contact_threshold``, ``feasibility_tolerance``).

    Returns
    -------
    JammingResult
        Its `stop_reason` says why the loop stopped, its `notes` what was repaired, retried
        or tried, and its `status` both in one sentence.

    Raises
    ------
    TypeError
        An unknown option; a removed one (``precompress_pressure``) names its replacement.
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
    packing = as_packing(packing, diameters, box)
    check_enough_particles(packing.n, packing.d)
    hint = None if network is None else check_network_hint(network, packing.n)
    return _Jammer(packing, settings, callback, checkpoint, start=start, hint=hint,
                   on_lp=on_lp).run()


def initial_step_bound(gap: float, settings: JamSettings) -> float:
    """First bound on displacements: the median nearest-neighbour surface gap, at least
    `INITIAL_STEP_FLOOR`, clipped to [min_step, max_step].

    From a compressed state the particles still travel much farther than their gaps to the
    jamming point; starting at the gap would spend several LPs growing the bound.

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
    (mean diameters): small for a compressed state, large for a loose start."""
    distances, neighbours = search.nearest_neighbours()
    sigma = 0.5 * (search.diameters + search.diameters[neighbours])
    return float(np.median(distances - sigma))


def next_step_bound(step: float, taken: Step, settings: JamSettings) -> float:
    """Adapt the displacement bound to the step just taken.

    - A stable particle held at the bound means the bound limited the step: multiply it by
      `step_growth`.
    - Far from jamming (fewer than half the particles stable) the contact network is a set of
      small clusters that all count as rattlers; if any particle with a contact sat at the
      bound, grow the bound too, otherwise keep it.
    - Otherwise the next bound is `step_margin` × the largest displacement of a stable
      particle, so that it follows the shrinking steps of the final approach (and the LP
      keeps fewer rows), but it does not shrink while it limits Γ (`Step.held_by_bound`):
      particles with d or fewer contacts count as rattlers, yet their neighbours can press
      them against the bound. Shrinking the bound with the stable particles' steps then
      stalled the loop at the smallest bound.
    """
    sparse_network = taken.stable_fraction < 0.5
    if (at_bound(taken.max_displacement, step)
            or (sparse_network and at_bound(taken.max_contacting, step))):
        proposed = step * settings.step_growth
    elif sparse_network:
        proposed = step
    elif taken.held_by_bound:
        proposed = max(step, settings.step_margin * taken.max_displacement)
    else:
        proposed = settings.step_margin * taken.max_displacement
    return float(np.clip(proposed, settings.min_step, settings.max_step))


class _Jammer:
    """State of one `jam` call (internal units: mean input diameter = 1).

    The state is the configuration (`positions`, `diameters`, their neighbour `search`), the
    step bound, the pairs forced into every LP, the networks the Newton stage refused, the
    warm-start basis, and the `History`; `policy` solves the LPs.
    """

    def __init__(self, packing: Packing, settings: JamSettings, callback,
                 checkpoint: str | os.PathLike | None = None, start: float | None = None,
                 hint: np.ndarray | None = None,
                 on_lp: Callable[[LPAttempt], None] | None = None):
        self.boundaries = packing.boundaries
        self.walled = not self.boundaries.is_periodic
        self.wall_axes = self.boundaries.wall_axes   # flat walls (layers form along them)
        # None in a periodic box: the geometry's fast path
        self.periodic = None if self.boundaries.is_periodic else self.boundaries.periodic
        self.history = History(packing.d, time.perf_counter() if start is None else start,
                               verbose=settings.verbose, zero_modes=self.boundaries.zero_modes)
        if self.walled:
            settings, hint = self._without_network_stages(settings, hint)
        self.settings = settings
        self.hint = hint
        self.callback = callback
        self.policy = SolverPolicy(settings, on_lp)
        self.scale = packing.mean_diameter
        self.n, self.d = packing.n, packing.d
        self.box = packing.box / self.scale
        self.positions = wrap(packing.positions / self.scale, self.box, self.periodic)
        self.diameters = packing.diameters / self.scale
        # the pin removes the container's zero modes: the translations along the periodic
        # axes (a wall holds the rest), and a cylinder's rotation
        self.fixed = np.zeros((self.n, self.d), dtype=bool)
        if settings.pin:
            self.fixed = pinned_coordinates(self.positions, self.box, np.ones(self.n, bool),
                                            self.boundaries)
        self.forced_walls = NO_PAIRS      # (particle, wall) rows forced into every LP
        self.wall_kicks = 0               # converged LPs left hypostatic between walls
        self.failed_networks: set[str] = set()
        self.newton_failure = ""          # why the last Newton stage was not certified
        self.forced = NO_PAIRS
        self.basis: Basis | None = None   # warm start of the next LP
        self.search = self._search(self.positions, self.diameters)
        check_input_overlaps(self.search, settings.overlap_tolerance)
        self.input_median_gap = median_gap(self.search)
        self.step = initial_step_bound(self.input_median_gap, settings)
        self.checkpoint = None if checkpoint is None else Checkpoint(
            checkpoint, "jam", checkpoint_signature(packing, settings), every=0.0)
        if self.checkpoint is not None:
            self._resume(self.checkpoint.load())

    # ----------------------------------------------------------------- checkpoint
    def _resume(self, state: dict | None) -> None:
        """Continue from the state saved by `_save_state`, if any."""
        if state is None:
            return
        self.positions, self.diameters = state["positions"], state["diameters"]
        self.search = self._search(self.positions, self.diameters)
        self.step = float(state["step"])
        self.forced = state["forced"].astype(np.int64).reshape(-1, 2)
        if "forced_walls" in state:
            self.forced_walls = state["forced_walls"].astype(np.int64).reshape(-1, 2)
        self.failed_networks = set(state["failed_networks"].tolist())
        self.history.restore({name: state[f"history_{name}"] for name in HISTORY_COLUMNS},
                             state["notes"].tolist())
        self.basis = (Basis(state["basis_row_keys"], state["basis_row_status"],
                            state["basis_col_status"]) if "basis_row_keys" in state else None)

    def _save_state(self) -> None:
        """Save the loop's state after an LP (`calippso.checkpoint`)."""
        if self.checkpoint is None:
            return
        history = self.history.to_array()
        state = {"positions": self.positions, "diameters": self.diameters, "step": self.step,
                 "forced": self.forced,
                 **({"forced_walls": self.forced_walls} if self.walled else {}),
                 "failed_networks": np.array(sorted(self.failed_networks), dtype=str),
                 "notes": np.array(self.history.notes, dtype=str),
                 **{f"history_{name}": history[name] for name in HISTORY_COLUMNS}}
        if self.basis is not None:
            state.update(basis_row_keys=self.basis.row_keys,
                         basis_row_status=self.basis.row_status,
                         basis_col_status=self.basis.col_status)
        self.checkpoint.save(state)

    # ----------------------------------------------------------------- helpers
    def packing(self) -> Packing:
        """The current configuration in the caller's units."""
        return Packing(self.positions * self.scale, self.diameters * self.scale,
                       self.box * self.scale, self.boundaries)

    def _search(self, positions: np.ndarray, diameters: np.ndarray) -> NeighborSearch:
        """The neighbour search of a configuration in this box (loop units)."""
        return NeighborSearch(positions, diameters, self.box, self.periodic)

    def _without_network_stages(self, settings: JamSettings,
                                hint: np.ndarray | None) -> tuple[JamSettings, None]:
        """Settings for a container: contact pivots, which do not know wall contacts yet,
        are switched off with a note, and so is a network hint (the network-first stage in a
        container reads its candidates from the gaps of pairs and walls,
        `calippso.container_guess`)."""
        if settings.pivots != "off":
            self.history.note(f"contact pivots skipped: not wall-aware yet "
                              f"({self.boundaries.describe()})")
        if hint is not None:
            self.history.note("the network hint was not used: in a container the network "
                              "is read from the gaps of the pairs and the walls")
        return settings.with_changes(pivots="off"), None

    def _walls(self, search: NeighborSearch, step: float, stable: np.ndarray | None,
               forced: np.ndarray) -> WallRows:
        """The LP's wall rows: the safe selection at this bound, the forced ones, and only
        those of `stable` particles when given."""
        walls = select_walls(search, step, self.boundaries)
        if forced.shape[0]:
            n_walls = wall_ids(self.d)
            extra = forced[~np.isin(forced[:, 0] * n_walls + forced[:, 1],
                                    walls.keys(n_walls))]
            if extra.shape[0]:
                more = wall_rows_of(search.positions, search.diameters, search.box,
                                    extra[:, 0], extra[:, 1], self.boundaries.cylinder_axes)
                walls = WallRows.concatenate([walls, more], self.d)
        if stable is not None:
            walls = walls.subset(stable[walls.particle])
        return walls

    def _fail(self, message: str) -> JammingError:
        return JammingError(message, packing=self.packing(), history=self.history.to_array())

    def _pairs(self, search: NeighborSearch, step: float, stable: np.ndarray | None,
               forced: np.ndarray) -> Pairs:
        """The LP's rows: the safe selection at this bound, the forced pairs, and only pairs
        of `stable` particles when given."""
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
               stable: np.ndarray | None = None, forced: np.ndarray = NO_PAIRS) -> Step:
        """Build and solve one LP by the solver policy (retries, fallbacks, warm start), and
        read its duals (`calippso.step.analyse`); a warm-started vertex with a hypostatic
        network is solved again from scratch (`Step.needs_cold_resolve`)."""
        lp_number = self.history.lps_solved + 1
        try:
            solved = self.policy.solve(
                lambda bound: build_lp(self._pairs(search, bound, stable, forced), self.n,
                                       self.d, bound, fixed,
                                       self._walls(search, bound, stable, self.forced_walls),
                                       self.boundaries.zero_modes),
                step, self.basis, lp_number)
        except LPFailed as error:
            raise self._fail(str(error)) from None
        if solved.note is not None:
            self.history.note(solved.note)
        offered = solved.warm_start is not None
        taken = analyse(solved.lp, solved.solution, self.settings, stable, offered)
        if taken.needs_cold_resolve:
            cold = self.policy.cold_resolve(solved, lp_number)
            if cold is not None:
                taken = analyse(solved.lp, cold, self.settings, stable, offered)
        return taken

    def _record(self, step: Step, min_gap: float, stage: str = "lp") -> Record:
        """The history record of an LP (the solver time of refused answers included)."""
        return self.history.add_lp(
            stage=stage, solver_time=step.solution.seconds + self.policy.take_discarded_seconds(),
            gamma=step.solution.gamma, max_displacement=step.max_displacement,
            rows=step.lp.n_rows, step_bound=step.lp.step_bound, n_contacts=step.n_contacts,
            n_stable=int(self.n - step.rattlers.sum()), force_balance=step.balance,
            min_gap=min_gap, phi=self.packing().phi)

    # ----------------------------------------------------------------- main loop
    def run(self) -> JammingResult:
        """The network-first stage, then the loop: step bound, LP, update, convergence."""
        settings = self.settings
        if settings.network_first != "off" and not self.history.records:
            certified = self._network_first()
            if certified is not None:
                return self._finish(*certified)
            if settings.network_first == "require":
                raise self._fail("network_first='require': no network guessed from the input "
                                 "was certified (" + self.history.notes[-1] + ")")
        network: ContactNetwork | None = None
        reason = StopReason.MAX_ITERS
        verifying = False
        while self.history.lps_solved < settings.max_iters:
            bound = largest_safe_step(self.search, self.step, self.boundaries)
            if bound < settings.min_step * VANISHING_STEP_FRACTION:
                raise self._fail("box too small: even a vanishing step would need pairs "
                                 "beyond half the box side")
            taken = self._solve(self.search, bound, self.fixed, forced=self.forced)
            positions = wrap(self.positions + taken.displacements, self.box, self.periodic)
            diameters = self.diameters * np.sqrt(1.0 + taken.solution.gamma)
            search = self._search(positions, diameters)
            close = search.pairs_near_contact()
            if self._walls_outside(search, taken):
                self.policy.discard(taken.solution.seconds)
                continue
            keys = taken.lp.pairs.i * self.n + taken.lp.pairs.j
            outside = (close.gaps < 0) & ~np.isin(close.i * self.n + close.j, keys)
            if outside.any():
                # A pair left out of the LP overlaps (round-off at the edge of the safe
                # selection): keep it from now on and solve this LP again.
                new = np.column_stack([close.i[outside], close.j[outside]])
                self.forced = np.unique(np.concatenate([self.forced, new]), axis=0)
                self.history.note(f"{int(outside.sum())} pair(s) outside the LP overlapped "
                                  f"after LP {self.history.lps_solved + 1}; re-solved with "
                                  f"them")
                self.policy.discard(taken.solution.seconds)
                continue
            self.positions, self.diameters, self.search = positions, diameters, search
            record = self._record(taken, min(close.smallest_gap(), walls_near_contact(
                search, self.boundaries).smallest_gap()))
            network = taken.network()
            converged = (record.sqrt_gamma_minus_1 < settings.tol_gamma
                         and taken.max_displacement < settings.tol_s
                         and taken.max_displacement < INSIDE_BOUND_FRACTION * bound
                         and not taken.held_by_bound)
            if verifying:
                verifying = False
                self.history.note("an LP at the Newton solution confirmed convergence"
                                  if converged else "the LP at the Newton solution did not "
                                  "confirm convergence; the loop went on")
            if self._stop_requested(record):
                reason = StopReason.STOPPED_BY_CALLBACK
                break
            self._check_box_size(taken)
            if ((converged or record.sqrt_gamma_minus_1 < WALL_KICK_GROWTH)
                    and self._kick_off_walls(record, network)):
                self._save_state()
                continue
            if converged:
                reason = StopReason.CONVERGED
                break
            if self.history.stalled(settings.tol_gamma):
                reason = StopReason.STALLED
                break
            # adapt from the bound the accepted LP had (a retry may have used a smaller one)
            self.step = next_step_bound(taken.lp.step_bound, taken, settings)
            self.basis = next_warm_start(taken.solution, taken.offered_warm_start,
                                         taken.max_displacement, taken.lp.step_bound)
            if (settings.newton and record.isostaticity_gap == 0 and record.n_contacts
                    and taken.max_displacement < settings.newton_start):
                refined, pivoted = self._newton_or_pivots(network)
                if refined is not None:
                    network = refined
                    if self._stop_requested(self.history.last):
                        reason = StopReason.STOPPED_BY_CALLBACK
                        break
                    if not settings.verify_newton:
                        reason = (StopReason.CERTIFIED_PIVOTS if pivoted
                                  else StopReason.CERTIFIED_NEWTON)
                        break
                    verifying, self.step = True, CLEANUP_STEP
            self._save_state()
        if network is None:
            raise self._fail(f"no LP was solved (max_iters = {settings.max_iters})")
        return self._finish(network, reason)

    def _kick_off_walls(self, record: Record, network: ContactNetwork) -> bool:
        """Whether a converged LP between walls was only a first-order stationary point, and
        the loop goes on from moved positions.

        Equal spheres at a flat wall form layers with centres in one plane. A particle whose
        contacts all lie in such a plane can leave it at no first-order cost, so the LP
        converges (or creeps by second-order steps) with a hypostatic network: a floppy
        mode. Leaving opens its contacts at second order, and Γ can then grow: not a jamming
        point. Such particles are moved out of their layer by up to `WALL_KICK_STEP` without
        any overlap (`calippso.walls.out_of_layer_moves`) and the loop goes on, at most
        `MAX_WALL_KICKS` times; each time adds a note.
        """
        if (not self.wall_axes or record.isostaticity_gap >= 0
                or self.wall_kicks >= MAX_WALL_KICKS):
            return False
        moved = out_of_layer_moves(self.search, self.wall_axes, network.wall_particle,
                                   WALL_KICK_STEP, WALL_KICK_TOUCHING, WALL_KICK_COPLANAR)
        if moved is None:
            return False
        self.wall_kicks += 1
        what = ("converged" if record.sqrt_gamma_minus_1 < self.settings.tol_gamma
                else f"grew sqrt(Gamma) by {record.sqrt_gamma_minus_1:.1e}")
        count = int(np.count_nonzero(np.any(moved != self.search.positions, axis=1)))
        self.history.note(f"LP {self.history.lps_solved} {what} with a hypostatic network "
                          f"between walls (gap {record.isostaticity_gap:+d}): {count} "
                          f"particle(s) held only within a layer parallel to a wall moved "
                          f"out of it, and the loop went on")
        self.positions = moved
        self.search = self._search(moved, self.diameters)
        self.step, self.basis = WALL_KICK_STEP, None
        return True

    def _walls_outside(self, search: NeighborSearch, taken: Step) -> bool:
        """Whether a particle crossed a wall whose row was left out of the LP (round-off at
        the edge of the safe selection); such rows are then forced into every LP, with a
        note, and the LP is solved again."""
        if not self.walled:
            return False
        near = walls_near_contact(search, self.boundaries)
        n_walls = wall_ids(self.d)
        outside = (near.gaps < 0) & ~np.isin(near.keys(n_walls), taken.lp.walls.keys(n_walls))
        if not outside.any():
            return False
        new = np.column_stack([near.particle[outside], near.wall[outside]])
        self.forced_walls = np.unique(np.concatenate([self.forced_walls, new]), axis=0)
        self.history.note(f"{int(outside.sum())} particle(s) crossed a wall left out of LP "
                          f"{self.history.lps_solved + 1}; re-solved with those walls")
        return True

    def _check_box_size(self, taken: Step) -> None:
        """Stop with an error when the particles grow to half the box side without jamming.

        Pairs are taken at their minimum image, which describes the packing only while every
        contact distance stays below half the box side. A small periodic box (few particles,
        high d) can leave every particle a rattler until the diameters approach that limit;
        the loop would then creep towards it with ever smaller steps.
        """
        half = self.search.half_period
        largest = float(self.diameters.max())
        if taken.stable_fraction == 0 and largest >= (1.0 - SMALL_BOX_MARGIN) * half:
            raise self._fail(
                f"box too small: the largest diameter has grown to {largest / half:.4f} x half "
                f"the box side after {self.history.lps_solved} LPs with no stable particle; "
                f"the packing cannot jam under the minimum-image convention in this box (use "
                f"more particles or a larger box)")

    def _stop_requested(self, record: Record) -> bool:
        return self.callback is not None and bool(self.callback(
            {**record.as_dict(), "iteration": self.history.lps_solved,
             "packing": self.packing()}))

    # ----------------------------------------------------------------- network first
    def _network_first(self) -> tuple[ContactNetwork, StopReason] | None:
        """The input's own contact network, certified by the Newton stage with no LP, and the
        stop reason (`StopReason.CERTIFIED_PIVOTS` when contact pivots repaired it); or None.

        Candidates come from `calippso.network_guess` (the hint first, then the gap
        spectrum); at most `MAX_NETWORK_GUESSES` are settled by `calippso.network_first`
        (restricted LP, Newton and contact pivots, a few rounds) and certified by the Newton
        stage. Each adds a history record (stage "guess"), a certified one also the pivot
        and Newton records; the notes say what happened.
        """
        if self.walled:
            return self._container_network_first()
        start = time.perf_counter()
        candidates = candidate_networks(self.search, self.d, self.hint)[:MAX_NETWORK_GUESSES]
        if not candidates:
            self.history.note("network first: the input holds no isostatic contact network "
                              "(not near a jamming point), so the LP loop ran")
            return None
        failures = []
        for candidate in candidates:
            settled, failure = settle_candidate(self.search, candidate, self.d,
                                                pivots=self.settings.pivots != "off")
            self._record_guess(candidate, settled, time.perf_counter() - start)
            if settled is not None:
                if settled.pivots is not None:
                    self._record_pivots(settled.pivots)
                network = ContactNetwork(settled.i, settled.j, np.zeros(settled.i.shape[0]),
                                         settled.rattlers, float("nan"), "none", from_lp=False)
                source = ("given as a hint" if candidate.source == "hint"
                          else "read from the gap spectrum")
                origin = (f"{source}, {settled.i.shape[0]} contacts"
                          + (f", {settled.opened} near pair(s) left open" if settled.opened
                             else "")
                          + (f", settled in {settled.rounds} rounds" if settled.rounds > 1
                             else ""))
                refined = self._newton(network, origin=origin, refined=settled.refinement)
                if refined is not None:
                    if self.callback is not None:
                        self.callback({**self.history.last.as_dict(), "iteration": 0,
                                       "packing": self.packing()})
                    return refined, (StopReason.NETWORK_FIRST if settled.pivots is None
                                     else StopReason.CERTIFIED_PIVOTS)
                failure = self.newton_failure
                # refused here, from the input's positions: the LP loop may still reach this
                # network, and its Newton stage must not skip it as tried before
                self.failed_networks.discard(network_key(settled.i, settled.j, self.n))
            failures.append(f"{candidate.source}: {failure}")
            start = time.perf_counter()
        self.history.note(f"network first: no guessed network was certified "
                          f"({'; '.join(failures)}), so the LP loop ran")
        return None

    def _container_network_first(self) -> tuple[ContactNetwork, StopReason] | None:
        """The network-first stage in a container: isostatic networks of pairs and wall
        contacts read from the gaps (`calippso.container_guess`), each certified by the
        Newton stage or refused; at most `MAX_NETWORK_GUESSES`. Each adds a history record
        (stage "guess"); the notes say what happened."""
        start = time.perf_counter()
        candidates = container_candidates(self.search, self.boundaries)[:MAX_NETWORK_GUESSES]
        if not candidates:
            self.history.note("network first: the input holds no isostatic network of "
                              "particle and wall contacts (not near a jamming point), so the "
                              "LP loop ran")
            return None
        failures = []
        for candidate in candidates:
            walls = candidate.walls
            network = ContactNetwork(candidate.pairs.i, candidate.pairs.j,
                                     np.zeros(len(candidate.pairs)), candidate.rattlers,
                                     float("nan"), "none", from_lp=False,
                                     wall_particle=walls.particle, wall=walls.wall,
                                     wall_forces=np.zeros(len(walls)))
            self.history.add_guess(seconds=time.perf_counter() - start,
                                   rows=network.n_contacts, n_contacts=network.n_contacts,
                                   n_stable=network.n_stable,
                                   min_gap=self.search.pairs_near_contact().smallest_gap(),
                                   phi=self.packing().phi)
            origin = (f"read from the gaps of the pairs and walls, {network.n_contacts} "
                      f"contacts, {len(walls)} with walls")
            refined = self._newton(network, origin=origin)
            if refined is not None:
                if self.callback is not None:
                    self.callback({**self.history.last.as_dict(), "iteration": 0,
                                   "packing": self.packing()})
                return refined, StopReason.NETWORK_FIRST
            failures.append(self.newton_failure)
            # refused from the input's positions: the LP loop may still reach this network
            self.failed_networks.discard(network.key())
            start = time.perf_counter()
        self.history.note(f"network first: no guessed network was certified "
                          f"({'; '.join(failures)}), so the LP loop ran")
        return None

    def _record_pivots(self, path: PivotPath) -> None:
        """History record (stage "pivots") and note of a path of contact pivots that reached
        a jamming point (`calippso.pivots`); its Newton certificate is recorded next."""
        refinement = path.refinement
        moved = Packing(refinement.positions * self.scale, refinement.diameters * self.scale,
                        self.box * self.scale)
        record = self.history.add_pivots(
            seconds=path.seconds, pivots=path.pivots,
            sqrt_gamma_minus_1=refinement.sqrt_gamma_minus_1,
            max_displacement=refinement.max_displacement, n_contacts=int(path.i.shape[0]),
            n_stable=int((~path.rattlers).sum()), min_gap=float("nan"), phi=moved.phi)
        self.history.note(describe_path(path))
        if self.callback is not None:
            self.callback({**record.as_dict(), "iteration": self.history.lps_solved,
                           "packing": moved})

    def _record_guess(self, candidate: Candidate, settled: SettledNetwork | None,
                      seconds: float) -> None:
        """History record of one candidate network (stage "guess"; no LP, nothing moves):
        the contacts and isostaticity gap of the settled network, or of the candidate's
        pairs when it did not settle."""
        close = self.search.pairs_near_contact()
        if settled is not None:
            n_contacts, stable = int(settled.i.shape[0]), ~settled.rattlers
        else:
            rattlers, kept = remove_rattlers(self.n, self.d, candidate.pairs.i,
                                             candidate.pairs.j)
            n_contacts, stable = int(kept.sum()), ~rattlers
        record = self.history.add_guess(seconds=seconds, rows=len(candidate.pairs),
                                        n_contacts=n_contacts, n_stable=int(stable.sum()),
                                        min_gap=close.smallest_gap(), phi=self.packing().phi)
        if self.callback is not None:
            self.callback({**record.as_dict(), "iteration": 0, "packing": self.packing()})

    # ----------------------------------------------------------------- Newton stage
    def _newton_or_pivots(self, network: ContactNetwork) -> tuple[ContactNetwork | None, bool]:
        """The Newton stage for an LP's isostatic network; with ``pivots="always"``, contact
        pivots from its jamming point when only non-positive forces refuse it.

        Returns
        -------
        (ContactNetwork or None, bool)
            The certified network (None if refused) and whether pivots reached it.
        """
        if (self.settings.pivots != "always"
                or network.key() in self.failed_networks):
            return self._newton(network), False
        refinement = refine_isostatic(self.positions, self.diameters, self.box, network.i,
                                      network.j, ~network.rattlers)
        if refinement is None:   # refused as the Newton stage would refuse it, solved once
            self.failed_networks.add(network.key())
            self.newton_failure = NEWTON_FAILED
            return None, False
        certified = self._newton(network, refined=refinement)
        if certified is not None or refinement.positive:
            return certified, False
        path, _ = pivot_to_jamming(self.positions, self.diameters, self.box, network.i,
                                   network.j, network.rattlers, refined=refinement)
        if path is None or not path.jammed:
            return None, False
        self._record_pivots(path)
        pivoted = ContactNetwork(path.i, path.j, np.zeros(path.i.shape[0]), path.rattlers,
                                 float("nan"), network.solver, from_lp=False)
        return self._newton(pivoted, refined=path.refinement, guessed=True), True

    def _newton(self, network: ContactNetwork, retry: bool = False, origin: str | None = None,
                refined: Refinement | None = None,
                guessed: bool = False) -> ContactNetwork | None:
        """Move to the certified jamming point of an isostatic network
        (`calippso.network.certify_network`); None unless certified.

        A network that failed once is not tried again, unless `retry` (at the end of the
        loop, from the converged positions). `origin` describes a network that did not come
        from an LP (the network-first stage), for the notes; `refined` is its Newton solution
        from the current positions when already computed (`calippso.network_first`). A
        `guessed` network (or one with an `origin`) did not come from an LP's duals: another
        touching pair refuses it (`calippso.network.certify_network`). On success a history
        record (stage "newton") and a note are added; on failure `newton_failure` says why.
        """
        key = network.key()
        if key in self.failed_networks and not retry:
            self.newton_failure = "tried before"
            return None
        began = time.perf_counter()
        certified, failure = certify_network(self.positions, self.diameters, self.box, network,
                                             guessed=guessed or origin is not None,
                                             refined=refined, boundaries=self.boundaries)
        if certified is None:
            self.failed_networks.add(key)
            self.newton_failure = failure
            return None
        self.positions, self.diameters = certified.positions, certified.diameters
        self.search = certified.search
        newton = certified.refinement
        self.history.add_newton(
            seconds=time.perf_counter() - began, sqrt_gamma_minus_1=newton.sqrt_gamma_minus_1,
            max_displacement=newton.max_displacement, n_contacts=network.n_contacts,
            n_stable=network.n_stable, force_balance=certified.balance,
            min_gap=certified.min_gap, phi=self.packing().phi)
        solved = (f"by Newton ({newton.iterations} iterations, {newton.factorizations} "
                  f"factorisation(s), residual {newton.residual:.0e})")
        if origin is None:
            self.history.note(f"contact equations solved {solved} after "
                              f"{self.history.lps_solved} LPs; certified by positive forces "
                              f"and no overlap")
        else:
            self.history.note(f"the input's own contact network ({origin}) solved {solved} "
                              f"with no LP; certified by positive forces and no overlap")
        return certified.network

    # ----------------------------------------------------------------- final forces
    def _finish(self, network: ContactNetwork, reason: StopReason) -> JammingResult:
        """The result: the network's forces repaired where needed (Newton, a clean-up LP,
        the touching pairs, least squares; `calippso.network`), no round-off overlap left,
        forces of mean 1, the status."""
        settings = self.settings
        converged = reason.jammed
        balance = network_balance(self.search, network, self.boundaries)
        if balance > settings.balance_tolerance and network.from_lp and converged:
            refined = self._newton(network, retry=True) if settings.newton else None
            if refined is not None:
                network, balance = refined, self.history.last.force_balance
        if (balance > settings.balance_tolerance and network.from_lp
                and not network.rattlers.all()):
            network, balance = self._cleanup(network)
        if converged:
            network, balance, note = touching_network(
                self.search, network, balance, self.d, settings.balance_tolerance,
                self.boundaries)
            self._note(note)
        if balance > settings.balance_tolerance and network.n_contacts:
            network, balance, note = polished_forces(self.search, network, balance,
                                                     self.boundaries)
            self._note(note)
        contacts = np.column_stack([network.i, network.j]).astype(np.int64)
        order = np.lexsort((contacts[:, 1], contacts[:, 0]))
        forces = network.forces[order]
        wall_contacts = np.column_stack([network.wall_particle, network.wall]).astype(np.int64)
        wall_order = np.lexsort((wall_contacts[:, 0], wall_contacts[:, 1]))
        wall_forces = network.wall_forces[wall_order]
        every_force = np.concatenate([forces, wall_forces])
        mean_force = every_force.mean() if every_force.size else 1.0
        shrink = remove_roundoff_overlaps(self.search, self.boundaries)
        if shrink is not None:
            self.diameters = self.diameters * shrink.factor
            self.search = shrink.search
            self.history.note(shrink.note)
            self.history.correct_min_gap(shrink.min_gap)
        gap = isostaticity_gap(network.n_contacts, network.n_stable, self.d,
                               self.boundaries.zero_modes)
        if self.walled and converged and gap < 0:
            self.history.note(f"not a certified jamming point: the LPs converged between walls "
                              f"with a hypostatic network (gap {gap:+d}), a floppy mode that "
                              f"moving particles out of their layers did not remove")
        notes = self._final_notes(reason)
        return JammingResult(
            packing=self.packing(), contacts=contacts[order], forces=forces / mean_force,
            wall_contacts=wall_contacts[wall_order], wall_forces=wall_forces / mean_force,
            rattlers=network.rattlers.copy(), converged=converged,
            status=status_sentence(reason, self.history.lps_solved, self.history.last_step(),
                                   network.n_stable, gap, notes),
            iterations=self.history.lps_solved, history=self.history.to_array(),
            wall_time=self.history.elapsed(), force_balance=balance,
            dual_normalization=network.normalization, solver=network.solver,
            stop_reason=reason, notes=notes)

    def _cleanup(self, network: ContactNetwork) -> tuple[ContactNetwork, float]:
        """Contacts and forces from an LP at the final positions, rattlers and one stable
        particle fixed, bound `CLEANUP_STEP`: its network and force balance."""
        stable = ~network.rattlers
        fixed = np.repeat(network.rattlers[:, None], self.d, axis=1)
        fixed |= pinned_coordinates(self.positions, self.box, stable, self.boundaries)
        cleanup = self._solve(self.search, CLEANUP_STEP, fixed, stable=stable)
        self._record(cleanup, self.history.last.min_gap, stage="cleanup")
        if cleanup.max_displacement > 0.5 * CLEANUP_STEP:
            self.history.note("the force clean-up LP found a floppy motion: the packing is "
                              "not rigid")
        return cleanup.network(), cleanup.balance

    def _note(self, note: str | None) -> None:
        if note is not None:
            self.history.note(note)

    def _final_notes(self, reason: StopReason) -> list[str]:
        """The run's notes, with the count of retried LPs and, for a loose input that did not
        converge, the advice to precompress it."""
        notes = list(self.history.notes)
        if self.policy.retried_lps > 1:
            notes.append(f"{self.policy.retried_lps} LPs in all needed a retry")
        if (not (reason.jammed or reason is StopReason.STOPPED_BY_CALLBACK)
                and self.input_median_gap > LOOSE_INPUT_GAP):
            notes.append(f"the input is loose (median nearest-neighbour gap "
                         f"{self.input_median_gap:.1e} mean diameters), where the LP loop "
                         f"alone can take hundreds of LPs: "
                         f"calippso.protocols.precompress(packing, 1e5) first compresses it "
                         f"by LS MD")
        return notes


def checkpoint_signature(packing: Packing, settings: JamSettings) -> dict:
    """What a jam checkpoint belongs to: a digest of the input and the settings that shape
    the sequence of LPs (all but `CHECKPOINT_FREE_SETTINGS`)."""
    options = {name: value for name, value in asdict(settings).items()
               if name not in CHECKPOINT_FREE_SETTINGS}
    signature = {"input": digest(packing.positions, packing.diameters, packing.box), **options}
    if not packing.boundaries.is_periodic:
        signature["boundaries"] = str(packing.boundaries)
    return signature
