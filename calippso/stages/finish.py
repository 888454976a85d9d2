"""The last stage: the network's forces repaired where needed, and the `JammingResult`.

In order: a converged LP network whose forces do not balance gets the Newton certificate
from the converged positions, else a clean-up LP (rattlers frozen); a converged network
takes the touching pairs of a degenerate packing (`calippso.geometry.contact_network.touching_network`);
forces that still do not balance are polished by least squares; round-off overlaps are shrunk
away (`calippso.geometry.contact_network.remove_roundoff_overlaps`); forces are scaled to mean 1.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..geometry.contacts import isostaticity_gap
from ..history import StopReason, status_sentence
from ..geometry.contact_network import (ContactNetwork, network_balance, polished_forces,
                                        remove_roundoff_overlaps, touching_network)
from ..certification.newton import pinned_coordinates
from ..geometry.packing import Packing
from ..result import JammingResult
from ..geometry.touching import TOUCHING_GAP, Touching, touching_outside_network
from .lp_step import record_lp, solve_lp
from .newton_stage import newton
from .state import LoopState, Run

__all__ = ["finish", "final_notes", "CLEANUP_STEP", "LOOSE_INPUT_GAP"]

#: Bound on displacements in the final clean-up LP (mean diameters); at a jammed state the
#: solution is ~0 and the bound is inactive. Also the bound of the LP that verifies a
#: Newton solution (``verify_newton``).
CLEANUP_STEP = 1e-3
#: An input whose median nearest-neighbour gap exceeds this (mean diameters) is loose: a run
#: that does not converge says that precompressing it (`calippso.protocols.precompress`) is
#: the remedy.
LOOSE_INPUT_GAP = 1e-3


def finish(run: Run, state: LoopState, network: ContactNetwork,
           reason: StopReason) -> JammingResult:
    """The result of the run that stopped at `state` with `network`, for `reason`.

    Returns
    -------
    JammingResult
        In the caller's units, with contacts sorted, forces of mean 1, the notes and the
        status sentence.
    """
    settings = run.settings
    converged = reason.jammed
    balance = network_balance(state.search, network, run.boundaries)
    certified = False    # by the Newton certificate: an isostatic network, positive forces
    if balance > settings.balance_tolerance and network.from_lp and converged:
        if settings.newton:
            state, outcome = newton(run, state, network, retry=True)
            if outcome.network is not None:
                network, balance = outcome.network, run.history.last.force_balance
                certified = True
    if (balance > settings.balance_tolerance and network.from_lp
            and not network.rattlers.all() and reason is not StopReason.TIME_LIMIT):
        network, balance = _cleanup(run, state, network)
    if converged:
        network, balance, note = touching_network(
            state.search, network, balance, run.d, settings.balance_tolerance, run.boundaries)
        _note(run, note)
    if balance > settings.balance_tolerance and network.n_contacts:
        network, balance, note = polished_forces(state.search, network, balance,
                                                 run.boundaries)
        _note(run, note)
    contacts = np.column_stack([network.i, network.j]).astype(np.int64)
    order = np.lexsort((contacts[:, 1], contacts[:, 0]))
    forces = network.forces[order]
    wall_contacts = np.column_stack([network.wall_particle, network.wall]).astype(np.int64)
    wall_order = np.lexsort((wall_contacts[:, 0], wall_contacts[:, 1]))
    wall_forces = network.wall_forces[wall_order]
    every_force = np.concatenate([forces, wall_forces])
    mean_force = every_force.mean() if every_force.size else 1.0
    shrink = remove_roundoff_overlaps(state.search, run.boundaries)
    if shrink is not None:
        state = replace(state, diameters=state.diameters * shrink.factor, search=shrink.search)
        run.history.note(shrink.note)
        run.history.correct_min_gap(shrink.min_gap)
    gap = isostaticity_gap(network.n_contacts, network.n_stable, run.d,
                           run.boundaries.zero_modes)
    if run.walled and converged and gap < 0:
        run.history.note(f"not a certified jamming point: the LPs converged between walls "
                         f"with a hypostatic network (gap {gap:+d}), a floppy mode that "
                         f"moving particles out of their layers did not remove")
    final = run.packing(state)
    touching = touching_outside_network(final, contacts[order], network.rattlers,
                                        wall_contacts[wall_order])
    if len(touching) and network.n_stable > 0:
        # the verdict says how the count changes when they are counted as contacts
        run.history.note(f"{len(touching)} more pair(s) touch outside the network with zero "
                         f"force (relative gap <= {TOUCHING_GAP:g}): counted as contacts, "
                         f"the isostaticity gap would be {gap + len(touching):+d}")
    if reason is StopReason.CONVERGED:
        # the tolerances were met; is a rigid network holding the packing? Not when none is
        # left or it is hypostatic, nor when the linear test finds an unjamming motion
        unjamming = None
        if network.n_stable > 0 and gap >= 0 and not certified:
            unjamming, undecided = _unjamming_motion(
                final, contacts[order], wall_contacts[wall_order], network.rattlers,
                touching)
            _note(run, unjamming)
            _note(run, undecided)
        if network.n_stable == 0 or gap < 0 or unjamming is not None:
            reason, converged = StopReason.NOT_RIGID, False
    notes = final_notes(run, reason)
    history = run.history
    return JammingResult(
        packing=final, contacts=contacts[order], forces=forces / mean_force,
        wall_contacts=wall_contacts[wall_order], wall_forces=wall_forces / mean_force,
        rattlers=network.rattlers.copy(), converged=converged,
        status=status_sentence(reason, history.lps_solved, history.last_step(),
                               network.n_stable, gap, notes),
        iterations=history.lps_solved, history=history.to_array(),
        wall_time=history.elapsed(), force_balance=balance,
        dual_normalization=network.normalization, solver=network.solver,
        stop_reason=reason, notes=notes)


def _cleanup(run: Run, state: LoopState,
             network: ContactNetwork) -> tuple[ContactNetwork, float]:
    """Contacts and forces from an LP at the final positions, rattlers and one stable
    particle fixed, bound `CLEANUP_STEP`: its network and force balance (history record
    stage "cleanup"). Its rows join stable particles only, so a move it makes is no proof of
    a floppy motion (a stable particle may move into a frozen rattler): rigidity is decided
    by `_unjamming_motion`."""
    stable = ~network.rattlers
    fixed = np.repeat(network.rattlers[:, None], run.d, axis=1)
    fixed |= pinned_coordinates(state.positions, run.box, stable, run.boundaries)
    cleanup = solve_lp(run, state, CLEANUP_STEP, fixed, stable=stable)
    record_lp(run, state, cleanup, run.history.last.min_gap, stage="cleanup")
    return cleanup.network(), cleanup.balance


def _unjamming_motion(packing: Packing, contacts: np.ndarray, wall_contacts: np.ndarray,
                      rattlers: np.ndarray, touching: Touching
                      ) -> tuple[str | None, str | None]:
    """Why the packing is not collectively jammed (None when it is), and a note when the
    test could not decide (its LP failed: the run keeps its reason, unverified).

    The linear test of `calippso.categories` (collective class) on the network's contacts
    and every other pair that touches (`touching`, `calippso.geometry.touching`): a motion that keeps every
    touching pair from overlapping to first order and moves stable particles is an
    unjamming motion, and the packing is not rigid whatever its contact count.
    """
    from ..categories import jamming_category

    every = JammingResult(
        packing=packing, contacts=np.concatenate([contacts, touching.pairs]),
        forces=np.zeros(0), rattlers=rattlers, converged=False, status="", iterations=0,
        wall_contacts=np.concatenate([wall_contacts, touching.walls]))
    try:
        category = jamming_category(every, up_to="collective")
    except (RuntimeError, ValueError) as error:   # the test's LP failed, or a refusal
        return None, f"collective jamming not verified: {error}"
    if category.category in ("collective", "strict"):
        return None, None
    what = "opens contacts" if category.opens_contacts else "keeps every contact closed"
    return (f"the linear test of collective jamming found an unjamming motion that {what} "
            f"(failed class: {category.failed}): the packing is not rigid"), None


def _note(run: Run, note: str | None) -> None:
    if note is not None:
        run.history.note(note)


def final_notes(run: Run, reason: StopReason) -> list[str]:
    """The run's notes, with the count of retried LPs and, for a loose input that did not
    converge, the advice to precompress it."""
    notes = list(run.history.notes)
    if run.policy.retried_lps > 1:
        notes.append(f"{run.policy.retried_lps} LPs in all needed a retry")
    if (not (reason.jammed or reason in (StopReason.STOPPED_BY_CALLBACK,
                                         StopReason.TIME_LIMIT))
            and run.input_median_gap > LOOSE_INPUT_GAP):
        notes.append(f"the input is loose (median nearest-neighbour gap "
                     f"{run.input_median_gap:.1e} mean diameters), where the LP loop "
                     f"alone can take hundreds of LPs: "
                     f"calippso.protocols.precompress(packing, 1e5) first compresses it "
                     f"by LS MD")
    return notes
