"""The LP step in a deformable box: the LP with the box's strain columns, and the move.

The rows are the pairs a step may bring into contact in the sheared cell, and in a container
the particle–wall pairs (`calippso.deformable.select_rows`, the bound halved until they stay
within half the shortest box vector; near a cylinder, the bound is the fixed box's
`calippso.lp.cylinder_step_limit` at most); the LP is the fixed box's with the strain columns (`strained_lp`), solved by
the run's solver policy; its answer is read by `analyse_strained`; the move strains the box
(`LoopState.cell`). The rest of the step (the record, `LPStep`, the convergence test) is
`calippso.stages.lp_step`'s.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..deformable import (analyse_strained, select_rows, smallest_gap, strain_matrix,
                          strain_scale, strained_lp)
from ..geometry.periodic import lattice_wrap
from ..lp import LinearProgram, cylinder_step_limit
from .lp_step import VANISHING_STEP_FRACTION, LPStep, record_lp, solved_lp
from .state import LoopState, Run

__all__ = ["strained_step"]


def strained_step(run: Run, state: LoopState) -> tuple[LoopState, LPStep]:
    """Solve the LP with the strain columns at the current configuration and move to its
    solution: centres by s', the box vectors by I + ε, diameters by √Γ*.

    Returns
    -------
    (LoopState, LPStep)
        The moved state (its `cell` strained) and the LP.

    Raises
    ------
    JammingError
        The box is too small for any step, or every backend failed.
    """
    d = run.d
    # the centres in one cell (the rows bound the image vectors by its diameter), centred on
    # the pinned particle (the strain's affine move then fits the bound)
    pinned = np.flatnonzero(run.fixed.any(axis=1))
    origin = (state.positions[pinned[0]] - 0.5 * state.cell.sum(axis=1) if pinned.size
              else np.zeros(d))
    positions = lattice_wrap(state.positions - origin, state.cell) + origin
    boundaries, box = run.boundaries, run.box
    bound = min(state.step, cylinder_step_limit(positions, state.diameters, box, boundaries))

    def rows_at(step: float):
        return select_rows(positions, state.diameters, state.cell, step, boundaries, box)

    while (rows := rows_at(bound)) is None:
        bound *= 0.5
        if bound < run.settings.min_step * VANISHING_STEP_FRACTION:
            raise run.fail(state, "box too small: even a vanishing step would need pairs "
                                  "beyond half the shortest box vector")
    scale = strain_scale(state.cell, boundaries.periodic)

    def build(step: float) -> LinearProgram:
        chosen = rows if step == bound else rows_at(step)
        return strained_lp(*chosen, run.n, step, scale, run.fixed, boundaries)

    solved = solved_lp(run, state, build, bound)
    taken = analyse_strained(solved.lp, solved.solution, run.settings, scale,
                             solved.warm_start is not None)
    x = taken.solution.x
    cell = (np.eye(d) + strain_matrix(x[run.n * d:-1], boundaries.periodic)) @ state.cell
    positions = lattice_wrap(positions + x[:run.n * d].reshape(run.n, d), cell)
    diameters = state.diameters * np.sqrt(1.0 + taken.solution.gamma)
    state = replace(state, positions=positions, diameters=diameters, cell=cell)
    record = record_lp(run, state, taken, smallest_gap(positions, diameters, cell, boundaries,
                                                       box))
    return state, LPStep(taken, taken.lp.step_bound, record, taken.network())
