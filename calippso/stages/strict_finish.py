"""The last stage in a deformable box: the forces with an isotropic stress, the stress tensor
and the strict certificate, and the `JammingResult`.

A network certified by the strict Newton stage keeps its forces when they balance at the
final geometry. Otherwise the last LP's network and forces are projected onto the forces in
equilibrium with an isotropic stress at the final positions
(`calippso.stages.strict_forces.balanced_network`), and a run that converged is tested for
strict jamming (`calippso.certification.strict_certificate.strict_category`). Round-off
overlaps (with walls too, in a container) are shrunk away first; forces are scaled to mean 1,
the wall contacts' included.
"""

from __future__ import annotations

import numpy as np

from ..certification.strict_certificate import certificate_note, strict_category
from ..deformable import smallest_gap, strict_zero_modes
from ..geometry.contact_network import ROUNDOFF_SHRINK_MARGIN, ContactNetwork
from ..geometry.contacts import contact_stress, isostaticity_gap
from ..geometry.packing import Packing
from ..history import StopReason, status_sentence
from ..result import JammingResult
from ..step import Step
from .finish import final_notes
from .state import LoopState, Run
from .strict_forces import StrictNetwork, balance_of, balanced_network

__all__ = ["strict_finish"]


def strict_finish(run: Run, state: LoopState, network: ContactNetwork, reason: StopReason,
                  last: Step | None) -> JammingResult:
    """The result of a deformable run that stopped at `state` with `network`, for `reason`;
    `last` is the last LP (its network is the fallback of a Newton network whose forces do
    not balance at the final geometry, its duals the strain certificate of the notes)."""
    history, settings, boundaries = run.history, run.settings, run.boundaries
    gap = smallest_gap(state.positions, state.diameters, state.cell, boundaries, run.box)
    diameters = state.diameters
    if gap < 0:
        diameters = diameters * (1.0 + gap) * (1.0 - ROUNDOFF_SHRINK_MARGIN)
        history.note(f"diameters scaled by 1 - {-gap:.1e} to remove round-off overlaps")
    packing = Packing.sheared(state.positions * run.scale, diameters * run.scale,
                              boundaries.box_cell(state.cell) * run.scale, boundaries)
    certified = False
    if not network.from_lp:
        final = StrictNetwork.of(network)
        balance = balance_of(packing, final)
        certified = balance <= settings.balance_tolerance
        if reason.jammed:
            reason = reason if certified else StopReason.CONVERGED
    if not certified:
        fallback = network if last is None or network.from_lp else last.network()
        final, balance = balanced_network(packing, StrictNetwork.of(fallback), history)
    i, j, forces = final.i, final.j, final.forces
    vectors = packing.minimum_image(packing.positions[i] - packing.positions[j])
    stress = contact_stress(vectors, forces, packing.volume)
    n_stable = int(final.rattlers.size - final.rattlers.sum())
    gap_count = isostaticity_gap(final.n_contacts, n_stable, run.d, strict_zero_modes(boundaries))
    if last is not None:
        history.note(certificate_note(last.lp, last.solution, stress, boundaries.periodic))
    category = None
    if certified:
        category = "strict"
        history.note("strictly jammed: positive forces in balance with an isotropic stress, "
                     "and a non-singular Jacobian of the strict contact equations")
    elif reason == StopReason.CONVERGED:
        if n_stable == 0 or gap_count < 0 or balance > settings.balance_tolerance:
            reason = StopReason.NOT_RIGID
        else:
            category = strict_category(packing, i, j, final.every_force, final.rattlers,
                                       history, final.walls)
            if category is not None and category != "strict":
                reason = StopReason.NOT_RIGID
    notes = final_notes(run, reason)
    return JammingResult(
        packing=packing, contacts=np.stack([i, j], axis=1).astype(np.int64),
        forces=forces, rattlers=final.rattlers, converged=reason.jammed,
        status=status_sentence(reason, history.lps_solved, history.last_step(), n_stable,
                               gap_count, notes),
        iterations=history.lps_solved, history=history.to_array(),
        wall_time=history.elapsed(), force_balance=balance,
        dual_normalization=np.nan if last is None else last.normalization,
        solver=network.solver, stop_reason=reason, notes=notes, box_mode="deformable",
        stress=stress, category=category, wall_contacts=final.walls,
        wall_forces=final.wall_forces)
