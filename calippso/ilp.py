"""The CALiPPSO loop: iterate linear programs until the packing is jammed.

`jam` checks the input (`calippso.inputs`) and runs the algorithm of docs/jamming.md in
`_run`, one stage after another (`calippso.stages`):

1. the network-first stage tries the input's own contact network, with no LP
   (`calippso.stages.network_first_stage`);
2. each LP step chooses the rows at the current bound, solves the LP, moves the particles by
   s* and inflates every diameter by √Γ* (`calippso.stages.lp_step`);
3. the loop stops when an LP meets the tolerances, or when the Newton stage certifies the
   jamming point of an isostatic LP network (`calippso.stages.newton_stage`); between walls,
   a hypostatic network is first moved out of its layers (`calippso.stages.wall_kick`);
4. otherwise the bound on the displacements adapts to the step just taken
   (`next_step_bound`): it grows when a stable particle was held back by it and shrinks with
   the displacements as the packing converges;
5. the finish repairs the forces where needed and shrinks away round-off overlaps
   (`calippso.stages.finish`).

Every stage takes the run (`calippso.stages.state.Run`) and the loop's state (a frozen
`LoopState`), returns the new state and what it found, and adds its records and notes to
the run's `calippso.history.History`; `StopReason` says why the loop stopped.

A deformable box (``box="deformable"``, `calippso.deformable`) runs the same loop: the
state holds the box vectors (`LoopState.cell`), the LP step adds the strain columns, the
Newton stage is the strict one (`calippso.stages.strict_newton_stage`, which also tries the
network hint before the first LP) and the finish `calippso.stages.strict_finish`.
"""

from __future__ import annotations

import os
import time
from dataclasses import replace
from typing import Callable

import numpy as np

from .geometry.boundaries import Boundaries
from .checkpoint import Checkpoint
from .deformable import DEFORMABLE_NOTE, check_strainable, smallest_gap, strict_zero_modes
from .deformable import INITIAL_STEP_FLOOR as DEFORMABLE_STEP_FLOOR
from .deformable import median_gap as deformable_median_gap
from .history import History, StopReason
from .inputs import as_packing, check_enough_particles, check_input_overlaps
from .geometry.neighbors import NeighborSearch
from .geometry.contact_network import ContactNetwork
from .certification.network_guess import check_network_hint
from .certification.newton import pinned_coordinates
from .geometry.packing import Packing, wrap
from .result import JammingResult
from .routes import jam_by_route
from .settings import JamSettings
from .solvers.policy import LPAttempt, SolverPolicy, next_warm_start
from .stages.finish import CLEANUP_STEP, finish
from .stages.strict_finish import strict_finish
from .stages.lp_step import LPStep, lp_step
from .stages.network_first_stage import Certified, network_first
from .stages.newton_stage import TRIED_BEFORE, newton_or_pivots
from .stages.strained_step import strained_step
from .stages.strict_newton_stage import strict_network_first
from .stages.saved import checkpoint_signature, resumed, save_state
from .stages.state import LoopState, Run
from .stages.wall_kick import WALL_KICK_GROWTH, kick_off_walls
from .step import Step, at_bound

__all__ = ["jam", "initial_step_bound", "next_step_bound"]

#: `check_box_size` stops a run whose largest diameter reaches (1 − this) × half the box
#: side with no stable particle.
SMALL_BOX_MARGIN = 1e-3
#: What `jam(..., box=...)` accepts as a string: the box stays, or deforms with the LPs.
BOX_MODES = ("fixed", "deformable")
#: Smallest first bound on displacements chosen by `initial_step_bound` (mean diameters).
INITIAL_STEP_FLOOR = 1e-3


def jam(packing, diameters=None, box=None, *, solver: str = "highs", tol_gamma: float = 1e-12,
        tol_s: float = 1e-9, max_iters: int = 1000, verbose: bool = False,
        callback: Callable[[dict], bool | None] | None = None,
        checkpoint: str | os.PathLike | None = None, network=None,
        on_lp: Callable[[LPAttempt], None] | None = None, route: str = "lp",
        max_displacement: float | None = None, **options) -> JammingResult:
    """Bring a configuration of hard (hyper)spheres to its jamming point with CALiPPSO.

    Parameters
    ----------
    packing : Packing or array_like, shape (N, d)
        The configuration, or its positions (then pass `diameters` and `box` too).
    diameters : array_like, shape (N,), optional
        Diameters, when `packing` is an array of positions.
    box : array_like, shape (d,) or float, or {"fixed", "deformable"}, optional
        Box side lengths, when `packing` is an array of positions. Or, as a string, what the
        box does: "fixed" (default) keeps it as given; "deformable" puts the box's strain
        in every LP (volume not growing), towards a strictly jammed packing
        (`calippso.deformable`: this loop with the strain columns and a strict Newton
        stage; periodic boxes, rectangular or sheared input, and containers with a
        periodic axis, strained on their periodic axes only; the LP route; the result
        holds the final box matrix and the stress tensor).
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
        ``converged=False``). A path of contact pivots also calls it after every pivot with
        a provisional record of stage "pivot", kept in no history: "pivots" taken so far,
        "non_positive" forces left, the pairs "released" and "closed", and the vertex's
        "packing" (its return value is not read).
    checkpoint : str or PathLike, optional
        File (``.npz``, appended when missing) where the loop's state is saved atomically
        after every LP (`calippso.checkpoint.Checkpoint`). If it exists, the run resumes from
        it (same input and settings required, otherwise ValueError naming what differs) and
        gives the result the uninterrupted run would have given.
    network : array_like, shape (M, 2), int, optional
        A contact network the caller knows (e.g. `GenerationResult.contacts` of a
        soft-sphere quench): pairs of particle indices. It is tried first by the
        network-first stage (``network_first``) and used only if the Newton certificate
        proves its jamming point (in a deformable box, by the strict Newton stage when it
        has the strict count).
    on_lp : callable, optional
        Called after every backend call of the run (each LP, its retries and fallbacks, the
        cold re-solves and the force clean-up LP) with a `calippso.solvers.LPAttempt`: the LP
        number, the role of the call, the backend's name, the `LinearProgram`, the basis
        offered as warm start, the `LPSolution` (None if the backend failed) and why the loop
        refused it (None if accepted). Its return value is ignored; an exception it raises
        ends the run and reaches the caller unchanged. For benchmarks and diagnostics.
    route : {"lp", "relaxed", "auto"}
        "lp" (default): the loop from the input. "relaxed": the input relaxed as soft
        spheres first (`generators.relax`), its overlap network tried by network first,
        then LPs if that fails; the jamming point is a nearby one, not the loop's. "auto":
        the relaxed route where the LP route is predicted to be slow
        (`calippso.routes.lp_route_slow`: N ≥ 1024 and an input far from a jamming point),
        said in the notes. Every route records on the result how far the jamming point lies
        from the input (`route`, `displacement_max`, `displacement_median`, `phi_input`).
    max_displacement : float, optional
        Largest distance a particle may move from the input, in mean diameters; a route
        that would move one further raises JammingError. None: 0.5 on the relaxed route,
        no bound on the LP route.
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
        ``network_first="require"`` and no guessed network was certified, or the route
        moved a particle further than `max_displacement`.
    """
    settings = JamSettings.from_options(solver=solver, tol_gamma=tol_gamma, tol_s=tol_s,
                                        max_iters=max_iters, verbose=verbose, **options)
    box_mode = "fixed"
    if isinstance(box, str):
        box_mode, box = box, None
        if box_mode not in BOX_MODES:
            raise ValueError(f"unknown box {box_mode!r}: choose one of {', '.join(BOX_MODES)}")
    if box_mode == "deformable":
        return _jam_deformable(packing, diameters, settings, callback, checkpoint, network,
                               on_lp, route, max_displacement)
    packing = as_packing(packing, diameters, box)
    check_enough_particles(packing.n, packing.d)
    settings = settings.resolved(packing.n, packing.d)

    def loop(start_packing: Packing, hint, saved, network_only: bool = False) -> JammingResult:
        start = time.perf_counter()
        hint = None if hint is None else check_network_hint(hint, start_packing.n)
        chosen = replace(settings, network_first="require") if network_only else settings
        run, state, saver, hint = _start(start_packing, chosen, callback, saved, start,
                                         hint, on_lp)
        return _run(run, state, saver, hint)

    return jam_by_route(packing, route, max_displacement, network, checkpoint, loop)


def _jam_deformable(packing, diameters, settings: JamSettings, callback, checkpoint, network,
                    on_lp, route: str, max_displacement: float | None) -> JammingResult:
    """`jam(..., box="deformable")`: the checks, then the loop with the box's strain in
    every LP (`calippso.deformable`), from `packing` as given (the LP route)."""
    if route != "lp" or max_displacement is not None:
        raise ValueError("box='deformable' takes the LP route from the input as given: pass "
                         "no route or max_displacement")
    if not isinstance(packing, Packing):
        raise TypeError("jam(positions, diameters, box=...) needs the box sides: pass a "
                        "Packing with box='deformable'")
    check_strainable(packing.boundaries)
    check_enough_particles(packing.n, packing.d)
    if settings.crossover == "auto":    # the strain columns are read from a vertex
        settings = settings.with_changes(crossover="on")
    start = time.perf_counter()
    hint = None if network is None else check_network_hint(network, packing.n)
    run, state, saver, hint = _start(packing, settings, callback, checkpoint, start, hint,
                                     on_lp, deformable=True)
    return replace(_run(run, state, saver, hint), phi_input=packing.phi)


def initial_step_bound(gap: float, settings: JamSettings,
                       floor: float = INITIAL_STEP_FLOOR) -> float:
    """First bound on displacements: the median nearest-neighbour surface gap, at least
    `floor` (`INITIAL_STEP_FLOOR`; a deformable box's is
    `calippso.deformable.INITIAL_STEP_FLOOR`), clipped to [min_step, max_step].

    From a compressed state the particles still travel much farther than their gaps to the
    jamming point; starting at the gap would spend several LPs growing the bound.

    Parameters
    ----------
    gap : float
        `median_gap` of the input configuration (mean diameters).
    settings : JamSettings
        `initial_step` overrides the rule; the result lies in [min_step, max_step].
    """
    step = settings.initial_step if settings.initial_step is not None else max(gap, floor)
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


def _run(run: Run, state: LoopState, checkpoint: Checkpoint | None,
         hint: np.ndarray | None) -> JammingResult:
    """The algorithm of docs/jamming.md: the network-first stage; then LP steps, each
    followed by the convergence test, the Newton stage when its network is isostatic and
    the next step bound, with the state saved after each; then the finish."""
    settings, history = run.settings, run.history
    deadline = None if settings.time_limit is None else time.perf_counter() + settings.time_limit
    if settings.network_first != "off" and not history.records:
        state, certified = _network_first(run, state, hint)
        if certified is not None:
            return _finish(run, state, certified.network, certified.reason, None)
    network: ContactNetwork | None = None
    reason, verifying, lp = StopReason.MAX_ITERS, False, None
    while history.lps_solved < settings.max_iters:
        state, lp = (lp_step if state.cell is None else strained_step)(run, state)
        network, converged = lp.network, lp.converged(settings)
        if verifying:
            verifying = False
            history.note("an LP at the Newton solution confirmed convergence" if converged
                         else "the LP at the Newton solution did not confirm convergence; "
                              "the loop went on")
        if run.stop_requested(lp.record, state):
            reason = StopReason.STOPPED_BY_CALLBACK
            break
        check_box_size(run, state, lp.taken)
        kicked = (kick_off_walls(run, state, lp.record, network)
                  if converged or lp.record.sqrt_gamma_minus_1 < WALL_KICK_GROWTH else None)
        if kicked is not None:
            state = kicked
            save_state(checkpoint, run, state)
            continue
        if converged:
            reason = StopReason.CONVERGED
            break
        if history.stalled(settings.tol_gamma):
            reason = StopReason.STALLED
            break
        state = _adapted(state, lp, settings)
        if lp.newton_due(settings):
            state, outcome = newton_or_pivots(run, state, network)
            if outcome.network is not None:
                network = outcome.network
                if run.stop_requested(history.last, state):
                    reason = StopReason.STOPPED_BY_CALLBACK
                    break
                if not settings.verify_newton:
                    reason = (StopReason.CERTIFIED_PIVOTS if outcome.pivoted
                              else StopReason.CERTIFIED_NEWTON)
                    break
                verifying, state = True, replace(state, step=CLEANUP_STEP)
        save_state(checkpoint, run, state)
        if _out_of_time(deadline):
            reason = StopReason.TIME_LIMIT
            break
    if network is None:
        raise run.fail(state, f"no LP was solved (max_iters = {settings.max_iters})")
    return _finish(run, state, network, reason, lp)


def _network_first(run: Run, state: LoopState,
                   hint: np.ndarray | None) -> tuple[LoopState, Certified | None]:
    """The network-first stage (`calippso.stages.network_first_stage`; in a deformable box,
    the strict Newton stage on the network hint); with ``network_first="require"``, the
    run's error when it certified nothing."""
    if state.cell is None:
        state, certified = network_first(run, state, hint)
    else:
        state, strict = strict_network_first(run, state, hint, TRIED_BEFORE)
        certified = None if strict is None else Certified(strict, StopReason.NETWORK_FIRST)
    if certified is None and run.settings.network_first == "require":
        why = run.history.notes[-1] if state.cell is None or hint is not None else "no hint"
        raise run.fail(state, f"network_first='require': no network guessed from the input "
                              f"was certified ({why})")
    return state, certified


def _finish(run: Run, state: LoopState, network: ContactNetwork, reason: StopReason,
            lp: LPStep | None) -> JammingResult:
    """The finish of the fixed box (`calippso.stages.finish`) or of a deformable one
    (`calippso.stages.strict_finish`, which reads the last LP's duals)."""
    if state.cell is None:
        return finish(run, state, network, reason)
    return strict_finish(run, state, network, reason, None if lp is None else lp.taken)


def _out_of_time(deadline: float | None) -> bool:
    """Whether the loop's time limit (`JamSettings.time_limit`) has passed."""
    return deadline is not None and time.perf_counter() >= deadline


def _adapted(state: LoopState, lp: LPStep, settings: JamSettings) -> LoopState:
    """The next LP's bound (`next_step_bound`, from the bound the accepted LP had: a retry
    may have used a smaller one) and warm start (`next_warm_start`). A deformable box
    starts cold only after a step that reached its bound (the bound then grows and the next
    optimum is far): the fixed box's rule, cold after any move of half the bound, would
    solve one LP in eight cold along the slide of a deformable box, at ten times the cost
    of a warm start from the last basis."""
    taken = lp.taken
    bound = taken.lp.step_bound
    moved = taken.max_displacement
    if state.cell is not None and not at_bound(moved, bound):
        moved = 0.0
    return replace(state, step=next_step_bound(bound, taken, settings),
                   basis=next_warm_start(taken.solution, taken.offered_warm_start, moved,
                                         bound))


def check_box_size(run: Run, state: LoopState, taken: Step) -> None:
    """Stop with an error when the particles grow to half the box side without jamming.

    Pairs are taken at their minimum image, which describes the packing only while every
    contact distance stays below half the box side. A small periodic box (few particles,
    high d) can leave every particle a rattler until the diameters approach that limit;
    the loop would then creep towards it with ever smaller steps.
    """
    if state.cell is not None:   # the strained LP step checks its own cell
        return
    half = state.search.half_period
    largest = float(state.diameters.max())
    if taken.stable_fraction == 0 and largest >= (1.0 - SMALL_BOX_MARGIN) * half:
        raise run.fail(
            state,
            f"box too small: the largest diameter has grown to {largest / half:.4f} x half "
            f"the box side after {run.history.lps_solved} LPs with no stable particle; "
            f"the packing cannot jam under the minimum-image convention in this box (use "
            f"more particles or a larger box)")


def _start(packing: Packing, settings: JamSettings,
           callback: Callable[[dict], bool | None] | None,
           checkpoint: str | os.PathLike | None, start: float, hint: np.ndarray | None,
           on_lp: Callable[[LPAttempt], None] | None, deformable: bool = False
           ) -> tuple[Run, LoopState, Checkpoint | None, np.ndarray | None]:
    """The run and the loop's first state (internal units: mean input diameter = 1),
    resumed from `checkpoint` if it holds a saved state; with the box's strain in every LP
    when `deformable` (`calippso.deformable`: the state holds the box vectors, the history
    counts strictly isostatic networks).

    Returns
    -------
    (Run, LoopState, Checkpoint or None, ndarray or None)
        With the checkpoint to save to and the network hint (None in a container).
    """
    boundaries = packing.boundaries
    history = History(packing.d, start, verbose=settings.verbose,
                      zero_modes=strict_zero_modes(boundaries) if deformable
                      else boundaries.zero_modes)
    if deformable:
        history.note(DEFORMABLE_NOTE)
        if hint is not None and not boundaries.is_periodic:
            history.note("the network hint was not used: in a container the network holds "
                         "wall contacts, which a hint of pairs does not give")
            hint = None
    elif not boundaries.is_periodic:
        settings, hint = _in_a_container(settings, hint, boundaries, history)
    policy = SolverPolicy(settings, on_lp)
    scale = packing.mean_diameter
    box = packing.box / scale
    periodic = None if boundaries.is_periodic else boundaries.periodic
    diameters = packing.diameters / scale
    if deformable:
        positions, cell = packing.positions / scale, packing.search_cell / scale
        deepest = smallest_gap(positions, diameters, cell, boundaries, box)
        if deepest < -settings.overlap_tolerance:
            raise ValueError(f"the input overlaps: the deepest relative gap is {deepest:.3e}, "
                             f"beyond overlap_tolerance {settings.overlap_tolerance:g}")
        search, gap = None, deformable_median_gap(positions, diameters, cell)
        step = initial_step_bound(gap, settings, DEFORMABLE_STEP_FLOOR)
    else:
        positions, cell = wrap(packing.positions / scale, box, periodic), None
        search = NeighborSearch(positions, diameters, box, periodic)
        check_input_overlaps(search, settings.overlap_tolerance)
        gap = median_gap(search)
        step = initial_step_bound(gap, settings)
    # the pin removes the container's zero modes: the translations along the periodic
    # axes (a wall holds the rest), and a cylinder's rotation
    fixed = np.zeros((packing.n, packing.d), dtype=bool)
    if settings.pin:
        fixed = pinned_coordinates(positions, box, np.ones(packing.n, bool), boundaries)
    run = Run(settings, boundaries, box, scale, fixed, gap, history, policy, callback)
    state = LoopState(positions, diameters, search, step, cell=cell)
    saver = None if checkpoint is None else Checkpoint(
        checkpoint, "jam", checkpoint_signature(packing, settings, deformable), every=0.0)
    if saver is not None:
        state = resumed(run, state, saver.load())
    return run, state, saver, hint


def _in_a_container(settings: JamSettings, hint: np.ndarray | None, boundaries: Boundaries,
                    history: History) -> tuple[JamSettings, None]:
    """Settings for a container: contact pivots, which do not know wall contacts yet, are
    switched off with a note, and so is a network hint (the network-first stage in a
    container reads its candidates from the gaps of pairs and walls,
    `calippso.certification.container_guess`)."""
    if settings.pivots != "off":
        history.note(f"contact pivots skipped: not wall-aware yet ({boundaries.describe()})")
    if hint is not None:
        history.note("the network hint was not used: in a container the network is read "
                     "from the gaps of the pairs and the walls")
    return settings.with_changes(pivots="off"), None
