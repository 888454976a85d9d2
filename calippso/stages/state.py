"""What every stage of the loop takes: the run (`Run`) and the loop's state (`LoopState`).

Both are in loop units: the mean input diameter is 1. `LoopState` is a frozen value; a stage
returns a new one. `Run` holds what one call of `calippso.jam` keeps fixed (settings, box,
units, pinned coordinates) and the two services the stages share: the `History` each stage
appends its records and notes to, and the `SolverPolicy` that solves every LP.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from ..geometry.boundaries import Boundaries
from ..errors import JammingError
from ..history import History, Record
from ..geometry.neighbors import NeighborSearch
from ..geometry.packing import Packing
from ..settings import JamSettings
from ..solvers import Basis
from ..solvers.policy import SolverPolicy

__all__ = ["Run", "LoopState", "NO_PAIRS"]

#: No pairs (or no (particle, wall) rows): nothing forced into the LP.
NO_PAIRS = np.zeros((0, 2), dtype=np.int64)


@dataclass(frozen=True)
class LoopState:
    """The configuration and what the loop carries from one LP to the next.

    Attributes
    ----------
    positions : ndarray, shape (N, d)
        Centres, wrapped into the box along its periodic axes.
    diameters : ndarray, shape (N,)
    search : NeighborSearch or None
        The neighbour search of `positions` and `diameters` (None in a deformable box, whose
        pairs come from `calippso.geometry.sheared_search`).
    step : float
        Bound on each displacement component in the next LP (mean diameters).
    forced : ndarray, shape (M, 2), int
        Pairs forced into every LP: left out once by the safe selection, they overlapped.
    forced_walls : ndarray, shape (K, 2), int
        (particle, wall) rows forced into every LP, for the same reason.
    basis : Basis or None
        Warm start of the next LP.
    failed_networks : frozenset of str
        Keys (`calippso.geometry.contact_network.network_key`) of networks the Newton stage refused.
    wall_kicks : int
        Times a hypostatic network between walls was moved out of its layers
        (`calippso.stages.wall_kick`).
    cell : ndarray, shape (d, d), or None
        The box vectors as columns in a deformable box (`calippso.deformable`), which the
        LPs strain (in a container, its search cell: the bounded axes padded,
        `calippso.geometry.boundaries.Boundaries.search_cell`); None when the box is the
        run's fixed one.
    """

    positions: np.ndarray
    diameters: np.ndarray
    search: NeighborSearch | None
    step: float
    forced: np.ndarray = field(default_factory=NO_PAIRS.copy)
    forced_walls: np.ndarray = field(default_factory=NO_PAIRS.copy)
    basis: Basis | None = None
    failed_networks: frozenset[str] = frozenset()
    wall_kicks: int = 0
    cell: np.ndarray | None = None

    def refused(self, key: str) -> LoopState:
        """This state with the network `key` among the refused ones."""
        return replace(self, failed_networks=self.failed_networks | {key})


@dataclass(frozen=True)
class Run:
    """What one call of `jam` keeps fixed, and the history and solver policy it shares.

    Attributes
    ----------
    settings : JamSettings
    boundaries : Boundaries
        Periodic axes, flat walls or a cylinder.
    box : ndarray, shape (d,)
        Box side lengths (loop units).
    scale : float
        The mean input diameter: loop units times `scale` are the caller's units.
    fixed : ndarray, shape (N, d), bool
        Coordinates pinned in every LP (the container's zero modes).
    input_median_gap : float
        Median nearest-neighbour gap of the input (`calippso.ilp.median_gap`).
    history : History
        One record per stage, and the notes; every stage appends to it.
    policy : SolverPolicy
        Solves every LP (retries, fallbacks, warm and cold starts).
    callback : callable or None
        Called with every record (`report`).
    """

    settings: JamSettings
    boundaries: Boundaries
    box: np.ndarray
    scale: float
    fixed: np.ndarray
    input_median_gap: float
    history: History
    policy: SolverPolicy
    callback: Callable[[dict], bool | None] | None = None

    @property
    def n(self) -> int:
        """Number of particles."""
        return self.fixed.shape[0]

    @property
    def d(self) -> int:
        """Dimension."""
        return self.fixed.shape[1]

    @property
    def walled(self) -> bool:
        """Whether some axis is bounded (flat walls or a cylinder)."""
        return not self.boundaries.is_periodic

    @property
    def periodic(self) -> np.ndarray | None:
        """The periodic axes, or None in a periodic box (the geometry's fast path)."""
        return None if self.boundaries.is_periodic else self.boundaries.periodic

    def search(self, positions: np.ndarray, diameters: np.ndarray) -> NeighborSearch:
        """The neighbour search of a configuration in this box."""
        return NeighborSearch(positions, diameters, self.box, self.periodic)

    def moved(self, state: LoopState, positions: np.ndarray,
              diameters: np.ndarray | None = None,
              search: NeighborSearch | None = None) -> LoopState:
        """`state` at new positions (and diameters), with their neighbour search."""
        diameters = state.diameters if diameters is None else diameters
        search = self.search(positions, diameters) if search is None else search
        return replace(state, positions=positions, diameters=diameters, search=search)

    def packing(self, state: LoopState) -> Packing:
        """The configuration of `state` in the caller's units (in its sheared box, when the
        box is deformable)."""
        if state.cell is not None:
            return Packing.sheared(state.positions * self.scale, state.diameters * self.scale,
                                   self.boundaries.box_cell(state.cell) * self.scale,
                                   self.boundaries)
        return self.packing_of(state.positions, state.diameters)

    def packing_of(self, positions: np.ndarray, diameters: np.ndarray) -> Packing:
        """A configuration in loop units, in the caller's units."""
        return Packing(positions * self.scale, diameters * self.scale, self.box * self.scale,
                       self.boundaries)

    def fail(self, state: LoopState, message: str) -> JammingError:
        """The error that ends the run, with the configuration of `state` and the history."""
        return JammingError(message, packing=self.packing(state),
                            history=self.history.to_array())

    def report(self, record: Record, packing: Packing, iteration: int) -> bool:
        """Hand `record`, with the configuration it describes and the LPs solved before it,
        to the callback; whether it asked to stop."""
        return self.callback is not None and bool(self.callback(
            {**record.as_dict(), "iteration": iteration, "packing": packing}))

    def stop_requested(self, record: Record, state: LoopState) -> bool:
        """Hand the record of an LP or a Newton stage of the loop to the callback, with the
        configuration of `state`; whether it asked to stop."""
        return self.callback is not None and self.report(record, self.packing(state),
                                                         self.history.lps_solved)
