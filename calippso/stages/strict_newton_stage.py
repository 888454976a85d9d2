"""The Newton stage in a deformable box: the strictly jammed point of an LP's network.

An LP network with the strict count, N_c = d (N_s − 1) + d(d+1)/2, goes to
`calippso.certification.strict_newton.refine_strict` (positions, strain and Γ); the point
is certified by positive forces, no pair of stable particles that is no contact overlapping
beyond the LPs' feasibility round-off, and no rattler overlapped beyond it once the
rattlers that the small move overlaps are moved out (`clear_rattlers`). The stage of the
loop is `calippso.stages.newton_stage.newton_or_pivots`, which calls this one when the box
is deformable; `strict_network_first` tries the caller's network hint the same way before
the first LP (the network-first stage of a deformable box). In a container the network's
wall contacts are equations too, and no particle may cross a wall that is no contact.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..certification.strict_newton import clear_rattlers, refine_strict
from ..deformable import container_walls
from ..geometry.contact_network import ContactNetwork
from ..geometry.contacts import isostaticity_gap
from ..geometry.periodic import lattice_minimum_image
from ..geometry.rattlers import remove_rattlers
from ..geometry.walls import wall_ids
from .state import LoopState, Run

__all__ = ["strict_newton", "strict_network_first", "NOT_STRICT", "RATTLER_OVERLAPPED",
           "STABLE_OVERLAP", "WALL_CROSSED"]

#: Why the stage refuses a network.
NOT_STRICT = "no strictly jammed point with positive forces"
RATTLER_OVERLAPPED = "a rattler stays overlapped at the strict point"
STABLE_OVERLAP = "two stable particles that are no contact overlap at the strict point"
WALL_CROSSED = "a stable particle crosses a wall that is no contact at the strict point"


def strict_newton(run: Run, state: LoopState, network: ContactNetwork, tried_before: str):
    """Move to the certified strictly jammed point of an LP network with the strict count.

    A network refused for its own sake (no solution, a non-positive force, stable particles
    overlapping) joins the refused ones; one refused for a rattler that its cage overlaps
    is tried again after the next LP, which moves the rattler.

    Returns
    -------
    (LoopState, ContactNetwork or None, str)
        The state at the strict point (box included) with a history record (stage
        "newton") and a note, and the network with the Newton forces; or the state, None
        and why it was refused (`tried_before` for a network refused before).
    """
    key = network.key()
    if key in state.failed_networks:
        return state, None, tried_before
    began = time.perf_counter()
    i, j, rattlers = network.i, network.j, network.rattlers
    vectors = lattice_minimum_image(state.positions[i] - state.positions[j], state.cell)
    refined = refine_strict(state.positions, state.diameters, state.cell, i, j, vectors,
                            ~rattlers, wall_particle=network.wall_particle, wall=network.wall,
                            boundaries=run.boundaries)
    if refined is None or not refined.positive:
        return state.refused(key), None, NOT_STRICT
    n = rattlers.size
    keys = np.sort(np.minimum(i, j) * n + np.maximum(i, j))
    moved, stable_overlap = clear_rattlers(refined.positions, refined.diameters,
                                           refined.matrix, keys, rattlers,
                                           run.settings.overlap_tolerance)
    if moved is None:
        return ((state.refused(key), None, STABLE_OVERLAP) if stable_overlap
                else (state, None, RATTLER_OVERLAPPED))
    crossing = _wall_crossers(run, moved, refined.diameters, network)
    if np.any(~rattlers[crossing]):
        return state.refused(key), None, WALL_CROSSED
    if crossing.size:
        return state, None, RATTLER_OVERLAPPED
    state = replace(state, positions=moved, diameters=refined.diameters, cell=refined.matrix)
    history = run.history
    history.add_newton(seconds=time.perf_counter() - began,
                       sqrt_gamma_minus_1=refined.sqrt_gamma_minus_1,
                       max_displacement=refined.max_displacement, n_contacts=i.shape[0],
                       n_stable=int(n - rattlers.sum()), force_balance=float("nan"),
                       min_gap=float("nan"), phi=run.packing(state).phi)
    history.note(f"strict contact equations (positions, strain, growth) solved by Newton "
                 f"({refined.iterations} iterations, {refined.factorizations} "
                 f"factorisation(s), residual {refined.residual:.0e}) after "
                 f"{history.lps_solved} LPs")
    return state, ContactNetwork(i, j, refined.forces, rattlers, float("nan"), network.solver,
                                 from_lp=False, wall_particle=network.wall_particle,
                                 wall=network.wall, wall_forces=refined.wall_forces), ""


def _wall_crossers(run: Run, positions: np.ndarray, diameters: np.ndarray,
                   network: ContactNetwork) -> np.ndarray:
    """The particles that cross a wall that is no contact of `network` beyond the LPs'
    feasibility round-off (`overlap_tolerance`), at `positions` (N, d) and `diameters`
    (N,); none in a periodic box. (A rattler that the strict point's small move or
    `clear_rattlers` pushed into a wall is moved by the next LP.)"""
    near = container_walls(positions, diameters, run.boundaries, run.box)
    n_walls = wall_ids(run.d)
    outside = ~np.isin(near.keys(n_walls), network.wall_particle * n_walls + network.wall)
    return near.particle[outside & (near.gaps < -run.settings.overlap_tolerance)]


def strict_network_first(run: Run, state: LoopState, hint: np.ndarray | None,
                         tried_before: str) -> tuple[LoopState, ContactNetwork | None]:
    """The strictly jammed point of the caller's network hint, with no LP: its pairs, the
    rattlers removed, through `strict_newton` when they have the strict count; a note says
    what came of it. (None, no note) without a hint: a deformable box guesses no network
    from the gaps."""
    if hint is None:
        return state, None
    i, j = np.minimum(hint[:, 0], hint[:, 1]), np.maximum(hint[:, 0], hint[:, 1])
    rattlers, kept = remove_rattlers(run.n, run.d, i, j)
    network = ContactNetwork(i[kept], j[kept], np.zeros(int(kept.sum())), rattlers,
                             float("nan"), "none", from_lp=False)
    history = run.history
    if not network.n_contacts or isostaticity_gap(
            network.n_contacts, int(run.n - rattlers.sum()), run.d, history.zero_modes):
        history.note("the network hint was not tried: it does not have the strict count "
                     "d (N_s - 1) + d(d+1)/2")
        return state, None
    state, certified, failure = strict_newton(run, state, network, tried_before)
    if certified is None:
        history.note(f"the network hint was refused by the strict Newton stage ({failure}); "
                     f"the LPs go on from the input")
    return state, certified
