"""The network-first stage: the input's own contact network, certified with no LP.

Candidates come from `calippso.certification.network_guess` in a periodic box (the hint first, then the
gap spectrum) and from `calippso.certification.container_guess` in a container (pairs and wall contacts
read from their gaps). At most `MAX_NETWORK_GUESSES` are tried: a periodic candidate is
settled first (`calippso.certification.network_first.settle_candidate`: restricted LP, Newton and contact
pivots, a few rounds; all candidates share one budget of wall time,
`STAGE_PIVOT_FACTORIZATIONS` sparse LU factorisations of the first network's Jacobian),
then each goes to the Newton stage's certificate. Each candidate adds
a history record (stage "guess"), a certified one also the pivot and Newton records; the
notes say what happened.

With ``crossover="off"``, a refused periodic input does not go back to the LP loop from
where it started: the loop starts from the point the first candidate reached (the jamming
point of the last network its rounds solved, `fallback_start`), with the bound its gap
spectrum suggests (the candidate's near gap), and every LP's network goes to Newton.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ..certification.container_guess import container_candidates
from ..history import StopReason
from ..geometry.contact_network import ContactNetwork, network_key
from ..certification.network_first import (PivotBudget, SettledNetwork,
                                           settle_candidate)
from ..certification.network_guess import Candidate, candidate_networks
from ..certification.newton import Refinement
from ..geometry.rattlers import remove_rattlers, separate_rattlers
from .newton_stage import newton, pivot_progress, record_pivots
from .state import LoopState, Run

__all__ = ["Certified", "network_first", "fallback_start", "MAX_NETWORK_GUESSES"]

#: Candidate networks the network-first stage settles at most (each costs a few sparse
#: factorisations).
MAX_NETWORK_GUESSES = 3
#: The LP loop's start after a refused candidate moves at most this many overlapping
#: particles apart by a small LP (`calippso.geometry.rattlers.separate_rattlers`); with more, that LP
#: is as large as the loop's own (minutes at N = 8192), and every diameter shrinks by the
#: worst overlap instead.
MAX_SEPARATED = 256


@dataclass(frozen=True)
class Certified:
    """A network the stage certified, and why the run stops there
    (`StopReason.NETWORK_FIRST`, or `StopReason.CERTIFIED_PIVOTS` when pivots repaired it)."""

    network: ContactNetwork
    reason: StopReason


def network_first(run: Run, state: LoopState,
                  hint: np.ndarray | None) -> tuple[LoopState, Certified | None]:
    """Try the input's own contact networks.

    Parameters
    ----------
    hint : ndarray, shape (M, 2), int, or None
        A network the caller knows, tried first (periodic boxes only).

    Returns
    -------
    (LoopState, Certified or None)
        The state at the certified jamming point, or the input's state when no candidate
        was certified (then a note says why, and the LP loop runs).
    """
    if run.walled:
        return _in_a_container(run, state)
    start = time.perf_counter()
    candidates = candidate_networks(state.search, run.d, hint)[:MAX_NETWORK_GUESSES]
    if not candidates:
        run.history.note("network first: the input holds no isostatic contact network "
                         "(not near a jamming point), so the LP loop ran")
        return state, None
    failures, first_reached = [], None
    budget = PivotBudget()
    for candidate in candidates:
        settled, failure, reached = settle_candidate(state.search, candidate, run.d,
                                                     pivots=run.settings.pivots != "off",
                                                     budget=budget,
                                                     on_pivot=pivot_progress(run))
        if first_reached is None and reached is not None:
            first_reached = (reached, candidate.near_gap)
        _record_guess(run, state, candidate, settled, time.perf_counter() - start)
        if settled is not None:
            if settled.pivots is not None:
                record_pivots(run, settled.pivots)
            network = ContactNetwork(settled.i, settled.j, np.zeros(settled.i.shape[0]),
                                     settled.rattlers, float("nan"), "none", from_lp=False)
            source = ("given as a hint" if candidate.source == "hint"
                      else "read from the gap spectrum")
            origin = (f"{source}, {settled.i.shape[0]} contacts"
                      + (f", {settled.opened} near pair(s) left open" if settled.opened
                         else "")
                      + (f", settled in {settled.rounds} rounds" if settled.rounds > 1
                         else ""))
            state, outcome = newton(run, state, network, origin=origin,
                                    refined=settled.refinement)
            if outcome.network is not None:
                run.report(run.history.last, run.packing(state), 0)
                return state, Certified(outcome.network,
                                        StopReason.NETWORK_FIRST if settled.pivots is None
                                        else StopReason.CERTIFIED_PIVOTS)
            failure = outcome.failure
            # refused here, from the input's positions: the LP loop may still reach this
            # network, and its Newton stage must not skip it as tried before
            state = _forget(state, network_key(settled.i, settled.j, run.n))
        failures.append(f"{candidate.source}: {failure}")
        start = time.perf_counter()
    run.history.note(f"network first: no guessed network was certified "
                     f"({'; '.join(failures)}), so the LP loop ran")
    if run.settings.crossover == "off" and first_reached is not None:
        state = fallback_start(run, state, *first_reached)
    return state, None


def fallback_start(run: Run, state: LoopState, reached: Refinement,
                   near_gap: float) -> LoopState:
    """The LP loop's start after a refused candidate: the jamming point it reached.

    Its rattlers were not moved while the diameters grew, so the particles that overlap
    there are moved apart by the small LP of `calippso.geometry.rattlers.separate_rattlers` (or,
    where that finds no room or more than `MAX_SEPARATED` particles overlap, every diameter
    shrinks by the worst overlap). The first
    bound is the candidate's near gap (clipped to the settings' range): the pairs that
    may still close lie within it.

    Parameters
    ----------
    reached : Refinement
        The jamming point of the last network the candidate's rounds solved.
    near_gap : float
        The candidate's `calippso.certification.network_guess.Candidate.near_gap`.
    """
    positions, diameters = reached.positions, reached.diameters
    search = run.search(positions, diameters)
    close = search.pairs_near_contact()
    overlapping = close.gaps < 0
    moved_apart = 0
    if overlapping.any():
        movable = np.zeros(run.n, dtype=bool)
        movable[close.i[overlapping]] = movable[close.j[overlapping]] = True
        separated = (separate_rattlers(positions, diameters, run.box, movable)
                     if movable.sum() <= MAX_SEPARATED else None)
        if separated is not None:
            positions, moved_apart = separated, int(movable.sum())
            search = run.search(positions, diameters)
        smallest = search.pairs_near_contact().smallest_gap()
        if smallest < 0:
            diameters = diameters * (1.0 + smallest)
            search = run.search(positions, diameters)
    step = float(np.clip(near_gap, run.settings.min_step, run.settings.max_step))
    growth = float(np.mean(diameters / state.diameters)) - 1.0
    run.history.note(f"the LP loop started from the jamming point of the first candidate's "
                     f"last network (diameters x (1 {growth:+.1e}), {moved_apart} overlapping "
                     f"particle(s) moved apart), with bound {step:.1e}")
    return replace(run.moved(state, positions, diameters, search), step=step)


def _in_a_container(run: Run, state: LoopState) -> tuple[LoopState, Certified | None]:
    """The stage in a container: isostatic networks of pairs and wall contacts read from the
    gaps (`calippso.certification.container_guess`), each certified by the Newton stage or refused."""
    start = time.perf_counter()
    candidates = container_candidates(state.search, run.boundaries)[:MAX_NETWORK_GUESSES]
    if not candidates:
        run.history.note("network first: the input holds no isostatic network of "
                         "particle and wall contacts (not near a jamming point), so the "
                         "LP loop ran")
        return state, None
    failures = []
    for candidate in candidates:
        walls = candidate.walls
        network = ContactNetwork(candidate.pairs.i, candidate.pairs.j,
                                 np.zeros(len(candidate.pairs)), candidate.rattlers,
                                 float("nan"), "none", from_lp=False,
                                 wall_particle=walls.particle, wall=walls.wall,
                                 wall_forces=np.zeros(len(walls)))
        run.history.add_guess(seconds=time.perf_counter() - start,
                              rows=network.n_contacts, n_contacts=network.n_contacts,
                              n_stable=network.n_stable,
                              min_gap=state.search.pairs_near_contact().smallest_gap(),
                              phi=run.packing(state).phi)
        origin = (f"read from the gaps of the pairs and walls, {network.n_contacts} "
                  f"contacts, {len(walls)} with walls")
        state, outcome = newton(run, state, network, origin=origin)
        if outcome.network is not None:
            run.report(run.history.last, run.packing(state), 0)
            return state, Certified(outcome.network, StopReason.NETWORK_FIRST)
        failures.append(outcome.failure)
        # refused from the input's positions: the LP loop may still reach this network
        state = _forget(state, network.key())
        start = time.perf_counter()
    run.history.note(f"network first: no guessed network was certified "
                     f"({'; '.join(failures)}), so the LP loop ran")
    return state, None


def _forget(state: LoopState, key: str) -> LoopState:
    """`state` with the network `key` no longer among the refused ones."""
    return replace(state, failed_networks=state.failed_networks - {key})


def _record_guess(run: Run, state: LoopState, candidate: Candidate,
                  settled: SettledNetwork | None, seconds: float) -> None:
    """Add the history record of one candidate network (stage "guess"; no LP, nothing
    moves): the contacts and isostaticity gap of the settled network, or of the candidate's
    pairs when it did not settle."""
    close = state.search.pairs_near_contact()
    if settled is not None:
        n_contacts, stable = int(settled.i.shape[0]), ~settled.rattlers
    else:
        rattlers, kept = remove_rattlers(run.n, run.d, candidate.pairs.i, candidate.pairs.j)
        n_contacts, stable = int(kept.sum()), ~rattlers
    record = run.history.add_guess(seconds=seconds, rows=len(candidate.pairs),
                                   n_contacts=n_contacts, n_stable=int(stable.sum()),
                                   min_gap=close.smallest_gap(), phi=run.packing(state).phi)
    run.report(record, run.packing(state), 0)
