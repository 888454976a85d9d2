"""In a container: a converged LP that is only a first-order stationary point.

Equal spheres at a flat wall form layers with centres in one plane. A particle whose contacts
all lie in such a plane can leave it at no first-order cost, so the LP converges (or creeps by
second-order steps) with a hypostatic network: a floppy mode. Leaving opens its contacts at
second order, and Γ can then grow: not a jamming point. `kick_off_walls` moves such particles
out of their layer (`calippso.geometry.walls.out_of_layer_moves`) and the loop goes on. A floppy mode
elsewhere (a wall row is linear, so the LP sees no second order at a wall) is left to the
LPs: the loop goes on from a fresh step bound and no warm start, which lets them move along
the mode far enough for its second order to open contacts. In a deformable box the layers
are looked for while its cell is rectangular; in a sheared one only the fresh bound is given.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..history import Record
from ..geometry.contact_network import ContactNetwork
from ..geometry.neighbors import NeighborSearch
from ..geometry.walls import out_of_layer_moves
from .state import LoopState, Run

__all__ = ["kick_off_walls", "WALL_KICK_STEP", "MAX_WALL_KICKS", "WALL_KICK_GROWTH"]

#: Largest move off a wall (mean diameters) after an LP that converged hypostatic between
#: walls, also the next LP's bound; how many times that is done.
WALL_KICK_STEP = 1e-3
MAX_WALL_KICKS = 20
#: ... done also when an LP between walls grows √Γ by less than this with a hypostatic
#: network: the LPs then creep along such a mode by second-order steps.
WALL_KICK_GROWTH = 1e-9
#: Pairs closer than this relative gap touch, and those with |n_μ| below the next value
#: lie in a layer parallel to the walls of axis μ (`calippso.geometry.walls.out_of_layer_moves`).
WALL_KICK_TOUCHING = 1e-6
WALL_KICK_COPLANAR = 1e-6


def kick_off_walls(run: Run, state: LoopState, record: Record,
                   network: ContactNetwork) -> LoopState | None:
    """The state to go on from after an LP in a container that converged (or crept) with a
    hypostatic network, or None when the network is not hypostatic, the box is periodic or
    `MAX_WALL_KICKS` were done.

    The particles held only within a layer along a flat wall move by up to `WALL_KICK_STEP`
    without any overlap; when there are none, nothing moves. Either way the next LP starts
    with that bound and no warm start. Adds a note.

    Parameters
    ----------
    record : Record
        The history record of the LP that converged or crept.
    network : ContactNetwork
        Its contact network (the wall contacts say which particles sit at a wall).
    """
    if (run.boundaries.is_periodic or record.isostaticity_gap >= 0
            or state.wall_kicks >= MAX_WALL_KICKS):
        return None
    what = ("converged" if record.sqrt_gamma_minus_1 < run.settings.tol_gamma
            else f"grew sqrt(Gamma) by {record.sqrt_gamma_minus_1:.1e}")
    axes = run.boundaries.wall_axes
    search = _search_of(run, state)
    moved = None if not axes or search is None else out_of_layer_moves(
        search, axes, network.wall_particle, WALL_KICK_STEP, WALL_KICK_TOUCHING,
        WALL_KICK_COPLANAR)
    restarted = replace(state, step=WALL_KICK_STEP, basis=None,
                        wall_kicks=state.wall_kicks + 1)
    if moved is None:
        # no particle lies in a layer: the floppy mode is elsewhere; a fresh bound (and no
        # warm start) lets the LPs move along it far enough for its second order to open
        # contacts
        run.history.note(f"LP {run.history.lps_solved} {what} with a hypostatic network in "
                         f"a container (gap {record.isostaticity_gap:+d}): the loop went on "
                         f"from a fresh step bound")
        return restarted
    count = int(np.count_nonzero(np.any(moved != search.positions, axis=1)))
    run.history.note(f"LP {run.history.lps_solved} {what} with a hypostatic network "
                     f"between walls (gap {record.isostaticity_gap:+d}): {count} "
                     f"particle(s) held only within a layer parallel to a wall moved "
                     f"out of it, and the loop went on")
    if state.cell is not None:
        return replace(restarted, positions=moved)
    return run.moved(restarted, moved)


def _search_of(run: Run, state: LoopState) -> NeighborSearch | None:
    """The neighbour search of `state`: its own in a fixed box, that of its cell's sides in
    a deformable box whose cell is rectangular, None in a sheared one."""
    if state.cell is None:
        return state.search
    sides = np.diag(run.boundaries.box_cell(state.cell))
    if np.any(state.cell != np.diag(np.diag(state.cell))):
        return None
    return NeighborSearch(state.positions, state.diameters, sides, run.periodic)
