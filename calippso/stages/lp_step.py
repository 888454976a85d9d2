"""The LP step: one linear program at the current bound, the update, and the convergence test.

`lp_step` chooses the rows at the largest safe bound (`calippso.lp`), has the LP solved
(`calippso.solvers.policy.SolverPolicy`), reads its answer (`calippso.step.analyse`), moves
the particles by s* and grows the diameters by √Γ*. If a pair or a wall left out of the LP
by the safe selection overlaps after the move (round-off at the edge of the selection), it
is forced into every later LP and the LP is solved again. `LPStep.converged` is the
convergence test, `LPStep.newton_due` the trigger of the Newton stage. A deformable box
takes its LP step in `calippso.stages.strained_step`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from ..history import Record
from ..lp import LinearProgram, build_lp, largest_safe_step, select_pairs, select_walls
from ..geometry.neighbors import NeighborSearch, Pairs
from ..geometry.contact_network import ContactNetwork, walls_near_contact
from ..geometry.packing import wrap
from ..settings import JamSettings
from ..solvers.policy import LPFailed, SolvedLP
from ..step import Step, analyse
from ..geometry.walls import WallRows, wall_ids, wall_rows_of
from .state import NO_PAIRS, LoopState, Run

__all__ = ["LPStep", "lp_step", "solve_lp", "solved_lp", "record_lp", "INSIDE_BOUND_FRACTION",
           "VANISHING_STEP_FRACTION"]

#: A step counts as converged only when its largest displacement stays below this fraction
#: of its bound (the bound did not hold it back).
INSIDE_BOUND_FRACTION = 0.5
#: A safe step bound below this fraction of `JamSettings.min_step` means that even a vanishing
#: step would need pairs beyond half the box side: the box is too small.
VANISHING_STEP_FRACTION = 1e-3


@dataclass(frozen=True)
class LPStep:
    """An accepted LP of the loop.

    Attributes
    ----------
    taken : Step
        Its answer: displacements, contacts, forces, whether the bound held a particle back.
    bound : float
        The bound it was asked for (a retry may have used a smaller one, `taken.lp`).
    record : Record
        Its history record.
    network : ContactNetwork
        Its contact network.
    """

    taken: Step
    bound: float
    record: Record
    network: ContactNetwork

    def converged(self, settings: JamSettings) -> bool:
        """√Γ* − 1 < `tol_gamma` and the largest displacement of a stable particle below
        `tol_s`, with the bound holding nothing back."""
        return (self.record.sqrt_gamma_minus_1 < settings.tol_gamma
                and self.taken.max_displacement < settings.tol_s
                and self.taken.max_displacement < INSIDE_BOUND_FRACTION * self.bound
                and not self.taken.held_by_bound)

    def newton_due(self, settings: JamSettings) -> bool:
        """Whether the Newton stage tries this LP's network: isostatic, with contacts, and
        a largest displacement below `newton_start` (after every LP with
        ``crossover="off"``, whose network is read by complementarity)."""
        return bool(settings.newton and self.record.isostaticity_gap == 0
                    and self.record.n_contacts
                    and (self.taken.max_displacement < settings.newton_start
                         or settings.crossover == "off"))


def lp_step(run: Run, state: LoopState) -> tuple[LoopState, LPStep]:
    """Solve the LP at the current configuration and move to its solution.

    Returns
    -------
    (LoopState, LPStep)
        The moved state (with any left-out pairs or walls now forced), and the LP.

    Raises
    ------
    JammingError
        The box is too small for any step, or every backend failed.
    """
    while True:
        bound = largest_safe_step(state.search, state.step, run.boundaries)
        if bound < run.settings.min_step * VANISHING_STEP_FRACTION:
            raise run.fail(state, "box too small: even a vanishing step would need pairs "
                                  "beyond half the box side")
        taken = solve_lp(run, state, bound, run.fixed, forced=state.forced)
        positions = wrap(state.positions + taken.displacements, run.box, run.periodic)
        diameters = state.diameters * np.sqrt(1.0 + taken.solution.gamma)
        search = run.search(positions, diameters)
        close = search.pairs_near_contact()
        widened = _force_left_out_walls(run, state, search, taken)
        if widened is None:
            widened = _force_left_out_pairs(run, state, close, taken)
        if widened is not None:   # solve this LP again with the left-out rows
            run.policy.discard(taken.solution.seconds)
            state = widened
            continue
        state = run.moved(state, positions, diameters, search)
        record = record_lp(run, state, taken, min(close.smallest_gap(), walls_near_contact(
            search, run.boundaries).smallest_gap()))
        return state, LPStep(taken, bound, record, taken.network())


def _force_left_out_pairs(run: Run, state: LoopState, close: Pairs,
                          taken: Step) -> LoopState | None:
    """The state with the pairs left out of the LP that overlap after its step forced into
    every LP (with a note), or None if there are none."""
    keys = taken.lp.pairs.i * run.n + taken.lp.pairs.j
    outside = (close.gaps < 0) & ~np.isin(close.i * run.n + close.j, keys)
    if not outside.any():
        return None
    new = np.column_stack([close.i[outside], close.j[outside]])
    run.history.note(f"{int(outside.sum())} pair(s) outside the LP overlapped after LP "
                     f"{run.history.lps_solved + 1}; re-solved with them")
    return replace(state, forced=np.unique(np.concatenate([state.forced, new]), axis=0))


def _force_left_out_walls(run: Run, state: LoopState, search: NeighborSearch,
                          taken: Step) -> LoopState | None:
    """The state with the walls a particle crossed after the LP, whose rows were left out of
    it, forced into every LP (with a note), or None if there are none."""
    if not run.walled:
        return None
    near = walls_near_contact(search, run.boundaries)
    n_walls = wall_ids(run.d)
    outside = (near.gaps < 0) & ~np.isin(near.keys(n_walls), taken.lp.walls.keys(n_walls))
    if not outside.any():
        return None
    new = np.column_stack([near.particle[outside], near.wall[outside]])
    run.history.note(f"{int(outside.sum())} particle(s) crossed a wall left out of LP "
                     f"{run.history.lps_solved + 1}; re-solved with those walls")
    return replace(state, forced_walls=np.unique(np.concatenate([state.forced_walls, new]),
                                                 axis=0))


def solve_lp(run: Run, state: LoopState, step: float, fixed: np.ndarray,
             stable: np.ndarray | None = None, forced: np.ndarray = NO_PAIRS) -> Step:
    """Build and solve one LP at the configuration of `state`, and read its answer.

    The solver policy retries, falls back and warm-starts from `state.basis`; a warm-started
    vertex with a hypostatic network is solved again from scratch
    (`Step.needs_cold_resolve`).

    Parameters
    ----------
    step : float
        Bound on each displacement component (mean diameters).
    fixed : ndarray, shape (N, d), bool
        Coordinates held in place.
    stable : ndarray, shape (N,), bool, optional
        Only the rows of these particles (the clean-up LP, rattlers frozen).
    forced : ndarray, shape (M, 2), int
        Pairs added to the safe selection (`state.forced_walls` are always added).
    """
    lp_number = run.history.lps_solved + 1
    solved = solved_lp(run, state, lambda bound: build_lp(
        _pairs(run, state.search, bound, stable, forced), run.n, run.d, bound, fixed,
        _walls(run, state.search, bound, stable, state.forced_walls),
        run.boundaries.zero_modes), step)
    offered = solved.warm_start is not None
    taken = analyse(solved.lp, solved.solution, run.settings, stable, offered)
    if taken.needs_cold_resolve:
        cold = run.policy.cold_resolve(solved, lp_number)
        if cold is not None:
            taken = analyse(solved.lp, cold, run.settings, stable, offered)
    return taken


def solved_lp(run: Run, state: LoopState, build: Callable[[float], LinearProgram],
            step: float) -> SolvedLP:
    """The LP of `build` at `step` solved by the run's solver policy (from `state.basis`),
    its note kept; the run's error when every backend failed."""
    try:
        solved = run.policy.solve(build, step, state.basis, run.history.lps_solved + 1)
    except LPFailed as error:
        raise run.fail(state, str(error)) from None
    if solved.note is not None:
        run.history.note(solved.note)
    return solved


def record_lp(run: Run, state: LoopState, taken: Step, min_gap: float,
              stage: str = "lp") -> Record:
    """Add the history record of an LP (the solver time of refused answers included) for the
    configuration of `state` it led to."""
    return run.history.add_lp(
        stage=stage, solver_time=taken.solution.seconds + run.policy.take_discarded_seconds(),
        gamma=taken.solution.gamma, max_displacement=taken.max_displacement,
        rows=taken.lp.n_rows, step_bound=taken.lp.step_bound, n_contacts=taken.n_contacts,
        n_stable=int(run.n - taken.rattlers.sum()), force_balance=taken.balance,
        min_gap=min_gap, phi=run.packing(state).phi,
        ipm_iterations=taken.solution.ipm_iterations)


def _pairs(run: Run, search: NeighborSearch, step: float, stable: np.ndarray | None,
           forced: np.ndarray) -> Pairs:
    """The LP's rows: the safe selection at this bound, the forced pairs, and only pairs of
    `stable` particles when given."""
    pairs = select_pairs(search, step)
    if forced.shape[0]:
        keys = pairs.i * run.n + pairs.j
        extra = forced[~np.isin(forced[:, 0] * run.n + forced[:, 1], keys)]
        if extra.shape[0]:
            more = search.pairs_of(extra[:, 0], extra[:, 1])
            pairs = Pairs(*(np.concatenate([a, b]) for a, b in zip(
                (pairs.i, pairs.j, pairs.vectors, pairs.distances, pairs.sigma),
                (more.i, more.j, more.vectors, more.distances, more.sigma))))
    if stable is not None:
        pairs = pairs.subset(stable[pairs.i] & stable[pairs.j])
    return pairs


def _walls(run: Run, search: NeighborSearch, step: float, stable: np.ndarray | None,
           forced: np.ndarray) -> WallRows:
    """The LP's wall rows: the safe selection at this bound, the forced ones, and only those
    of `stable` particles when given."""
    walls = select_walls(search, step, run.boundaries)
    if forced.shape[0]:
        n_walls = wall_ids(run.d)
        extra = forced[~np.isin(forced[:, 0] * n_walls + forced[:, 1], walls.keys(n_walls))]
        if extra.shape[0]:
            more = wall_rows_of(search.positions, search.diameters, search.box,
                                extra[:, 0], extra[:, 1], run.boundaries.cylinder_axes)
            walls = WallRows.concatenate([walls, more], run.d)
    if stable is not None:
        walls = walls.subset(stable[walls.particle])
    return walls
