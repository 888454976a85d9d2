"""The Newton stage: the certified jamming point of an isostatic network, and contact pivots.

`newton` moves the configuration to the jamming point of a network and accepts it only with
the certificate of `calippso.certification.certificate.certify_network` (positive forces, no other overlap, a
non-singular Jacobian). `newton_or_pivots` is the stage of the LP loop: with
``crossover="off"``, a network refused only for non-positive forces is taken to the jamming
point by contact pivots (`calippso.certification.pivots`) and certified there.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..certification.certificate import certify_network
from ..geometry.contact_network import ContactNetwork
from ..certification.newton import MIN_FORCE_RATIO, NEWTON_FAILED, Refinement, refine_isostatic
from ..certification.pivots import PivotPath, Swap, describe_path, pivot_to_jamming
from ..certification.pivots.path import PivotHook
from ..geometry.contacts import isostaticity_gap
from ..history import Record
from .state import LoopState, Run
from .strict_newton_stage import strict_newton

__all__ = ["NewtonOutcome", "newton", "newton_or_pivots", "record_pivots", "pivot_progress",
           "TRIED_BEFORE", "PIVOT_PRINT_SECONDS",
           "INTERIOR_PIVOTS", "INTERIOR_PIVOT_LPS"]

#: A verbose run prints a line on a path of contact pivots at most this often (seconds).
PIVOT_PRINT_SECONDS = 5.0
#: Why a network that the Newton stage refused once is not tried again.
TRIED_BEFORE = "tried before"
#: With ``crossover="off"`` the Newton stage runs after every LP: contact pivots repair its
#: network only when at most this many forces come out non-positive (a network further off
#: is left to the next LP, which sees all of it at once).
INTERIOR_PIVOTS = 40
#: ... and take at most this many times the wall time of the LP just solved: past it, the
#: next LP, from where the pivots stopped, is the cheaper way on.
INTERIOR_PIVOT_LPS = 1.0


@dataclass(frozen=True)
class NewtonOutcome:
    """What the Newton stage made of a network.

    Attributes
    ----------
    network : ContactNetwork or None
        The certified network (forces from its self-stress), or None if refused.
    failure : str
        Why it was refused ("" when certified).
    pivoted : bool
        Whether contact pivots led to it.
    """

    network: ContactNetwork | None
    failure: str = ""
    pivoted: bool = False


def newton(run: Run, state: LoopState, network: ContactNetwork, *, retry: bool = False,
           origin: str | None = None, refined: Refinement | None = None,
           guessed: bool = False) -> tuple[LoopState, NewtonOutcome]:
    """Move to the certified jamming point of an isostatic network.

    Parameters
    ----------
    network : ContactNetwork
        Its contacts and rattlers.
    retry : bool
        Try it even if it was refused before (at the end of the loop, from the converged
        positions).
    origin : str, optional
        Where a network that did not come from an LP comes from (the network-first stage),
        for the notes.
    refined : Refinement, optional
        Its Newton solution from the current positions, when already computed.
    guessed : bool
        It did not come from an LP's duals (nor does one with an `origin`): another
        touching pair refuses it (`calippso.certification.certificate.certify_network`).

    Returns
    -------
    (LoopState, NewtonOutcome)
        The state at the jamming point if certified (with a history record, stage
        "newton", and a note), otherwise with the network among the refused ones.
    """
    key = network.key()
    if key in state.failed_networks and not retry:
        return state, NewtonOutcome(None, TRIED_BEFORE)
    began = time.perf_counter()
    certified, failure = certify_network(state.positions, state.diameters, run.box, network,
                                         guessed=guessed or origin is not None,
                                         refined=refined, boundaries=run.boundaries)
    if certified is None:
        return state.refused(key), NewtonOutcome(None, failure)
    state = run.moved(state, certified.positions, certified.diameters, certified.search)
    solution = certified.refinement
    run.history.add_newton(
        seconds=time.perf_counter() - began, sqrt_gamma_minus_1=solution.sqrt_gamma_minus_1,
        max_displacement=solution.max_displacement, n_contacts=network.n_contacts,
        n_stable=network.n_stable, force_balance=certified.balance,
        min_gap=certified.min_gap, phi=run.packing(state).phi)
    solved = (f"by Newton ({solution.iterations} iterations, {solution.factorizations} "
              f"factorisation(s), residual {solution.residual:.0e})")
    if origin is None:
        run.history.note(f"contact equations solved {solved} after "
                         f"{run.history.lps_solved} LPs; certified by positive forces "
                         f"and no overlap")
    else:
        run.history.note(f"the input's own contact network ({origin}) solved {solved} "
                         f"with no LP; certified by positive forces and no overlap")
    return state, NewtonOutcome(certified.network)


def newton_or_pivots(run: Run, state: LoopState,
                     network: ContactNetwork) -> tuple[LoopState, NewtonOutcome]:
    """The Newton stage for an LP's isostatic network; with ``crossover="off"`` (unless
    ``pivots="off"``), contact pivots from its jamming point when only non-positive forces
    refuse it. In a deformable box, the strictly jammed point of the network
    (`calippso.stages.strict_newton_stage`)."""
    if state.cell is not None:
        state, certified, failure = strict_newton(run, state, network, TRIED_BEFORE)
        return state, NewtonOutcome(certified, failure)
    settings = run.settings
    pivots = settings.crossover == "off" and settings.pivots != "off"
    if not pivots or network.key() in state.failed_networks:
        return newton(run, state, network)
    refinement = refine_isostatic(state.positions, state.diameters, run.box, network.i,
                                  network.j, ~network.rattlers)
    if refinement is None:   # refused as the Newton stage would refuse it, solved once
        return state.refused(network.key()), NewtonOutcome(None, NEWTON_FAILED)
    state, outcome = newton(run, state, network, refined=refinement)
    if outcome.network is not None or refinement.positive:
        return state, outcome
    budget = {}
    if settings.crossover == "off":
        forces = refinement.forces
        if np.count_nonzero(forces <= MIN_FORCE_RATIO * forces.max()) > INTERIOR_PIVOTS:
            return state, outcome
        budget = {"time_limit": INTERIOR_PIVOT_LPS * run.history.last_step().solver_time}
    path, _ = pivot_to_jamming(state.positions, state.diameters, run.box, network.i,
                               network.j, network.rattlers, refined=refinement,
                               on_pivot=pivot_progress(run), **budget)
    if path is None:
        return state, outcome
    if not path.jammed:
        if settings.crossover == "off" and path.pivots:
            state = _where_the_pivots_stopped(run, state, path)
        return state, outcome
    record_pivots(run, path)
    pivoted = ContactNetwork(path.i, path.j, np.zeros(path.i.shape[0]), path.rattlers,
                             float("nan"), network.solver, from_lp=False)
    state, outcome = newton(run, state, pivoted, refined=path.refinement, guessed=True)
    return state, replace(outcome, pivoted=True)


def _where_the_pivots_stopped(run: Run, state: LoopState, path: PivotPath) -> LoopState:
    """The state at the end of a path of contact pivots that did not reach the jamming point
    within its budget (``crossover="off"``): its vertex has a larger Γ than the LP's network
    at its Newton point, and no overlap, so the next LP starts there and the pivots' work
    is kept. Adds the path's history record (stage "pivots") and a note."""
    record_pivots(run, path, note=f"after LP {run.history.lps_solved}, {path.pivots} contact "
                                  f"pivot(s) in {path.seconds:.2f} s did not reach a jamming "
                                  f"point; the next LP starts where they stopped")
    return run.moved(state, path.refinement.positions, path.refinement.diameters)


def record_pivots(run: Run, path: PivotPath, note: str | None = None) -> None:
    """Add the history record (stage "pivots") and the note of a path of contact pivots: by
    default `describe_path`'s, for a path that reached a jamming point (its Newton
    certificate is recorded next)."""
    refinement = path.refinement
    moved = run.packing_of(refinement.positions, refinement.diameters)
    record = run.history.add_pivots(
        seconds=path.seconds, pivots=path.pivots,
        sqrt_gamma_minus_1=refinement.sqrt_gamma_minus_1,
        max_displacement=refinement.max_displacement, n_contacts=int(path.i.shape[0]),
        n_stable=int((~path.rattlers).sum()), min_gap=float("nan"), phi=moved.phi)
    run.history.note(describe_path(path) if note is None else note)
    run.report(record, moved, run.history.lps_solved)


def pivot_progress(run: Run) -> PivotHook | None:
    """The run's view of a path of contact pivots as it goes: after every pivot, the
    callback gets a provisional record (stage "pivot", kept in no history: the pivots so far
    in "pivots", the vertex's contacts and φ, and the keys "non_positive", "released" and
    "closed"); a verbose run prints a line at most every `PIVOT_PRINT_SECONDS`. None when the
    run has neither."""
    if run.callback is None and not run.history.verbose:
        return None
    began = time.perf_counter()
    printed = [began]

    def on_pivot(pivots: int, swap: Swap, vertex: Refinement, stable: np.ndarray) -> None:
        n_stable = int(stable.sum())
        n_contacts = run.d * (n_stable - 1) + 1
        now = time.perf_counter()
        if run.history.verbose and now - printed[0] >= PIVOT_PRINT_SECONDS:
            printed[0] = now
            print(f"     pivot {pivots}: {swap.non_positive} force(s) non-positive, "
                  f"released {swap.released}, closed {swap.closed}, {now - began:.1f} s",
                  flush=True)
        if run.callback is None:
            return
        packing = run.packing_of(vertex.positions, vertex.diameters)
        record = Record(
            stage="pivot", wall_time=run.history.elapsed(), solver_time=now - began,
            sqrt_gamma_minus_1=float("nan"), max_displacement=float("nan"), rows=n_contacts,
            step_bound=float("nan"), n_contacts=n_contacts,
            isostaticity_gap=isostaticity_gap(n_contacts, n_stable, run.d,
                                              run.history.zero_modes),
            force_balance=float("nan"), min_gap=float("nan"), phi=packing.phi, pivots=pivots)
        run.callback({**record.as_dict(), "iteration": run.history.lps_solved,
                      "packing": packing, "non_positive": swap.non_positive,
                      "released": swap.released, "closed": swap.closed})

    return on_pivot
