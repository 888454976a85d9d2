"""Soft-sphere quench: harmonic spheres minimised with FIRE towards vanishing pressure, then shrunk.

O'Hern, Silbert, Liu & Nagel, PRE 68, 011306 (2003): near a jamming point the energy minimum
of harmonic spheres has pressure p ∝ φ − φ_J, and its overlap network at p → 0⁺ is the
contact network of a hard-sphere jamming point. One uniform shrink of the diameters removes
the overlaps; `calippso.jam` can then prove the jamming point from that network.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from calippso.geometry.boundaries import CYLINDER, PERIODIC, WALLS, Boundaries
from calippso.geometry.packing import Packing, ball_volume
from calippso.geometry.rattlers import remove_rattlers

from . import _fire, _lbfgs, _newton
from ._checks import (check_boundaries, check_diameters, check_dimension, check_phi,
                      check_positive, phi_estimate, remove_roundoff_overlap, wall_gaps)
from .checkpoint import Checkpoint, Resumable, digest
from ._progress import Progress
from .cells import verlet_lists
from .periodic import all_periodic, wrap_into_box
from .initial import poisson
from .result import GenerationResult, make_history

__all__ = ["soft_quench", "default_target_pressure", "pressure_ladder"]

#: FIRE base time step, in units of √(m σ²/ε) for the smallest diameter σ, at d = 3. It is
#: scaled by √(3/d) because the stiffest mode grows with the number of contacts (~2d).
DT0_3D = 0.1
# The measurements behind these values are in docs/notes/soft-quench-protocol.md.
#: Δt_max / Δt0: half of Bitzek et al.'s 10, with which FIRE did not converge in dense packings.
DT_MAX_FACTOR = 5.0
#: Force tolerance of the intermediate minimisations, relative to the mean pair force: a
#: looser one leaves more relaxation to the last minimisation, the dearest.
INTERMEDIATE_TOLERANCE = 1e-4
#: Force floor of the convergence test, × machine epsilon × the box side: safely above the
#: round-off of the pair vectors (~ε L), below which no force converges.
ROUNDOFF_FORCE = 50.0
#: Pressure of the first minimisation (from random centres), and the largest factor between
#: the pressures of two successive ones (a geometric ladder down to `TARGET_AIM` × the
#: target): the factor that took the fewest FIRE steps, each start near its minimum.
FIRST_PRESSURE = 1e-2
PRESSURE_REDUCTION = 0.1
#: The last minimisation holds the pressure at this fraction of the target: safely below it,
#: and not much lower, since its cost grows as p^(-1/2) (the softest modes).
TARGET_AIM = 0.5
#: Pairs count as contacts when they overlap by more than this (relative): between the
#: round-off overlap of a rattler touching its cage and the smallest overlap of a stable pair,
#: so that a rattler touching d + 1 neighbours does not pass for a stable particle.
TOUCH = 1e-12
#: Relative gap left on the most overlapping pair by the final shrink (round-off of |r|/σ at
#: box sides of ~30 σ is ~1e-14).
SHRINK_GAP = 1e-12
#: phi_start defaults to this factor × a typical jamming density of the dimension.
PHI_START_FACTOR = 1.12
#: The default `target_pressure` (`default_target_pressure`): `EARLY_TARGET_PRESSURE` in a
#: periodic box with at most `EARLY_STOP_MAX_N` particles in the `EARLY_STOP_DIMENSIONS`,
#: else `LATE_TARGET_PRESSURE`. Stopping a decade earlier skips the slowest minimisations of
#: the ladder, and `calippso.jam` still settles the network left there with no LP; larger
#: packings, d = 5 and containers need the network of the lower pressure (measured in
#: docs/notes/soft-quench-protocol.md; d = 2 was not).
EARLY_TARGET_PRESSURE = 1e-6
LATE_TARGET_PRESSURE = 1e-7
EARLY_STOP_MAX_N = 4096
EARLY_STOP_DIMENSIONS = (3, 4)
#: The Verlet skin follows the rebuild rate. At each list rebuild within a minimisation it is
#: multiplied by √((`REBUILD_COST` / steps since the last build) / w), w the share of the
#: listed pairs that did not overlap at that build (by at most `SKIN_STEP` either way): the
#: cost of the rebuilds per step (∝ 1/skin) then matches that of the listed pairs that do not
#: interact (∝ skin). After a minimisation without a rebuild it becomes `SKIN_DRIFT_FACTOR` ×
#: the largest drift seen (at least `SKIN_MIN` mean diameters): near jamming the particles move
#: ~1e-3 σ per minimisation, and a thin skin lists fewer pairs. It never exceeds the caller's.
SKIN_DRIFT_FACTOR = 4.0
SKIN_MIN = 0.02
#: Cost of a list rebuild (sort, cell lists, pair lists), in force evaluations: 17–24 at
#: N = 1024 in d = 4 and N = 8192 in d = 3 (`bench/soft_quench.py --kernels`).
REBUILD_COST = 20.0
#: Largest factor of one skin adaptation at a rebuild.
SKIN_STEP = 2.0
#: FIRE steps (L-BFGS force evaluations) between two pauses of a minimisation, where a
#: checkpoint may be written (a pause changes no result: `_fire.fire_run` and
#: `_lbfgs.lbfgs_run` continue from the state they return).
PAUSE_STEPS = 1000
#: Newton iterations (solves) between two pauses: each costs a sparse factorisation, as much
#: as 10³–10⁴ FIRE steps.
NEWTON_PAUSE_STEPS = 10
#: minimiser="newton" alternates two phases within each minimisation: the dimension's
#: first-order minimiser ("auto": FIRE or L-BFGS) for up to `NEWTON_AFTER_STEPS` steps, then
#: damped Newton (`_newton.newton_run`) for up to `NEWTON_PHASE_SOLVES` solves, and so on
#: until converged. Newton converges in ~20 solves once the overlap network has settled
#: (d = 3, N = 1024, from a FIRE minimum to 1e-4 of the mean force down to 1e-6), but while
#: contacts still form it finds them a few per solve; the first-order phase finds them
#: cheaply, and most minimisations end within it.
NEWTON_AFTER_STEPS = 20_000
NEWTON_PHASE_SOLVES = 40
#: Layout of `_SoftSpheres.method` with minimiser="newton": the phase (`BASE_PHASE` or
#: `NEWTON_PHASE`), the steps taken in it, then its kernel's state from `PHASE_STATE` on.
PHASE, PHASE_TAKEN, PHASE_STATE = 0, 1, 2
BASE_PHASE, NEWTON_PHASE = 0.0, 1.0
#: Code of a quench that its watch stopped (`quench_and_shrink`), beside the kernels' codes
#: (`_fire.CONVERGED`, `_fire.REBUILD`, `_fire.OUT_OF_STEPS`).
HALTED = 3
#: Code of a quench that its `settled` test ended after a rung (`quench_and_shrink`).
SETTLED = 4
#: `soft_quench` and `relax` ask their `settle` only about overlap networks with at most
#: this many contacts beyond the isostatic count when the caller gives no other bound.
SETTLE_EXCESS = 4
#: The minimisers `soft_quench` offers ("auto" picks one by the dimension).
MINIMISERS = ("auto", "fire", "lbfgs", "newton")
#: Where each minimiser's state array holds λ = ln a.
LOG_SCALE_SLOT = {"fire": 4, "lbfgs": _lbfgs.LOG_SCALE, "newton": _newton.LOG_SCALE}
#: With minimiser="auto", L-BFGS from this dimension on, FIRE below. In d = 4 and 5 (N = 1024,
#: seeds 1–5) L-BFGS took fewer force evaluations than FIRE took steps, and its slowest run
#: fewer in d = 5. In d = 3 neither is faster at every N (seed 1, quench s, FIRE / L-BFGS:
#: 11 / 33 at N = 2048, 410 / 531 at 4096, 1334 / 233 at 8192, 977 / 1235 at 16384), and
#: each L-BFGS evaluation costs 1.3–1.7 FIRE steps (docs/generators.md, Run time).
LBFGS_FROM_DIMENSION = 4
#: The boundary kinds `soft_quench` handles.
BOUNDARY_KINDS = (PERIODIC, WALLS, CYLINDER)


class _SoftSpheres(Resumable):
    """Harmonic spheres in a box, periodic or closed by flat walls along each axis, or in a
    cylinder, kept sorted by cell for cache locality.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Start positions (mean diameters).
    nominal : ndarray, shape (N,)
        Nominal diameters s_i (mean 1); the diameters are `scale` · s_i.
    box : ndarray, shape (d,)
    skin : float
        Largest Verlet skin, in mean diameters (the skin adapts below it).
    minimiser : str
        "fire" (`_fire.fire_run`), "lbfgs" (`_lbfgs.lbfgs_run`) or "newton" (phases of
        `base` and of `_newton.newton_run`, `NEWTON_AFTER_STEPS`).
    periodic : ndarray, shape (d,), bool, optional
        Periodic axes; flat harmonic walls at 0 and L_μ along the others (`_fire`) except
        the cylinder's. None: every axis periodic.
    cylinder : tuple of int, optional
        The two axes of a harmonic cylinder (`_fire.harmonic_forces`), or ().

    Attributes
    ----------
    x, v : ndarray, shape (N, d)
        Positions and velocities in the sorted order.
    s : ndarray, shape (N,)
        Nominal diameters in the sorted order.
    ids : ndarray of int64, shape (N,)
        Original index of each slot.
    scale : float
        Diameter scale a.
    steps : int
        FIRE steps (L-BFGS force evaluations, Newton solves) so far.
    base : str
        The first-order kernel of minimiser="newton": "lbfgs" from `LBFGS_FROM_DIMENSION`
        on, "fire" below.
    solves : int
        Newton solves so far (among `steps`).
    """

    def __init__(self, positions: np.ndarray, nominal: np.ndarray, box: np.ndarray,
                 skin: float, minimiser: str = "fire",
                 periodic: np.ndarray | None = None, cylinder: tuple[int, ...] = ()) -> None:
        n, d = positions.shape
        self.box = box
        self.periodic = all_periodic(d) if periodic is None else np.asarray(periodic,
                                                                            dtype=np.bool_)
        self.cylinder = tuple(int(axis) for axis in cylinder)
        # (the kernels' form: the two axes, or _fire.NO_CYLINDER)
        self.circle = self.cylinder if self.cylinder else _fire.NO_CYLINDER
        self.max_skin = skin
        self.skin = skin
        self.x = positions.copy()
        self.v = np.zeros_like(self.x)
        self.f = np.zeros_like(self.x)
        self.s = nominal.copy()
        self.ids = np.arange(n, dtype=np.int64)
        self.scale = 1.0
        self.steps = 0
        self.rebuilds = 0
        volume = float(np.prod(box)) * (np.pi / 4 if self.cylinder else 1.0)
        self.phi_unit = float(np.sum(ball_volume(d, nominal / 2))) / volume
        self.dt0 = DT0_3D * np.sqrt(3.0 / d) * float(nominal.min())
        self.force_floor = ROUNDOFF_FORCE * np.finfo(np.float64).eps * float(box.max())
        self.x_built = self.x.copy()
        self.scale_built = self.scale
        self.lists: tuple[np.ndarray, ...] = ()
        self.minimiser = minimiser
        self.base = "lbfgs" if d >= LBFGS_FROM_DIMENSION else "fire"
        self.solves = 0
        # The minimisation in progress: the minimiser's state (`_fire.fire_run`,
        # `_lbfgs.lbfgs_run`; with "newton" the phase, its steps and its kernel's state,
        # `PHASE`; empty between two minimisations) and L-BFGS's history (s, y
        # pairs: `memory_x` shape (2, HISTORY, N d), `memory_u` shape (4, HISTORY)), its
        # steps so far, the rebuild count at its start, its steps at the last list build and
        # the last drift; the share of the listed pairs that did not overlap at the build.
        self.method = np.empty(0)
        self.memory_x = np.empty((2, 0, n * d))
        self.memory_u = np.empty((4, 0))
        self.taken = 0
        self.built = 0
        self.built_at = 0
        self.drift = 0.0
        self.waste = 0.0

    #: Attributes (and their types) that make up the whole state at a pause (`minimise`) or
    #: between two minimisations.
    STATE = {"x": np.float64, "v": np.float64, "s": np.float64, "ids": np.int64,
             "x_built": np.float64, "method": np.float64, "memory_x": np.float64,
             "memory_u": np.float64, "scale": float, "skin": float,
             "scale_built": float, "drift": float, "steps": int, "rebuilds": int,
             "taken": int, "built": int, "built_at": int, "solves": int}

    def restore(self, saved: dict) -> None:
        """`Resumable.restore`, then the lists of a minimisation in progress."""
        super().restore(saved)
        self.f = np.zeros_like(self.x)
        if self.method.size:
            self._build_lists()

    @property
    def phi(self) -> float:
        """Packing fraction at the current scale."""
        return self.phi_unit * self.scale ** self.x.shape[1]

    def rebuild(self) -> None:
        """Wrap (along the periodic axes), re-sort the particles by cell, and rebuild the
        Verlet lists."""
        wrap_into_box(self.x, self.box, self.periodic)
        order = _fire.cell_order(self.x, self.box, self.scale * self.s.max() + self.skin)
        self.x, self.v, self.s, self.ids = (self.x[order], self.v[order], self.s[order],
                                            self.ids[order])
        if self.memory_x.size:
            n, d = self.x.shape
            self.memory_x = np.ascontiguousarray(
                self.memory_x.reshape(2, -1, n, d)[:, :, order].reshape(2, -1, n * d))
        self.x_built = self.x.copy()
        self.scale_built = self.scale
        self._build_lists()
        self.rebuilds += 1

    def _build_lists(self) -> None:
        """Verlet lists of the positions and scale at the last build, and the share of
        their pairs that do not overlap (`waste`)."""
        self.lists = _fire.pair_lists(*verlet_lists(self.x_built, self.box,
                                                    self.scale_built * self.s, self.skin,
                                                    self.periodic))
        listed = len(self.lists[1])
        overlapping = len(_fire.contact_pairs(self.x_built, self.s, self.scale_built, self.box,
                                              *self.lists[:2], 0.0, self.periodic)[0])
        self.waste = 1.0 - overlapping / listed if listed else 1.0

    def _adapt_skin(self) -> None:
        """Before a rebuild within a minimisation: the skin that balances the cost of the
        rebuilds against that of the non-overlapping listed pairs (see `REBUILD_COST`)."""
        interval = max(self.taken - self.built_at, 1)
        factor = np.sqrt(REBUILD_COST / interval / max(self.waste, np.finfo(float).eps))
        factor = min(max(factor, 1.0 / SKIN_STEP), SKIN_STEP)
        self.skin = min(self.max_skin, max(SKIN_MIN, factor * self.skin))
        self.built_at = self.taken

    @property
    def kernel(self) -> str:
        """The kernel of the minimisation in progress: the minimiser's, or with "newton" that
        of its phase (`base` or "newton")."""
        if self.minimiser != "newton":
            return self.minimiser
        return "newton" if self.method[PHASE] == NEWTON_PHASE else self.base

    def _begin(self, kernel: str) -> None:
        """Start `kernel` from rest at the current positions and scale: its fresh state in
        `method` (after the phase and its steps, with minimiser="newton"), L-BFGS's empty
        history."""
        self.v[:] = 0.0
        log_scale = np.log(self.scale)
        self.memory_x = np.empty((2, 0, self.x.size))
        self.memory_u = np.empty((4, 0))
        if kernel == "lbfgs":
            state = _lbfgs.new_state(log_scale)
            self.memory_x = np.zeros((2, _lbfgs.HISTORY, self.x.size))
            self.memory_u = np.zeros((4, _lbfgs.HISTORY))
        elif kernel == "newton":
            state = _newton.new_state(log_scale)
        else:
            state = np.array([self.dt0, _fire.ALPHA_START, 0.0, 0.0, log_scale, 0.0])
        if self.minimiser == "newton":
            phase = NEWTON_PHASE if kernel == "newton" else BASE_PHASE
            state = np.concatenate([[phase, 0.0], state])
        self.method = state

    def minimise(self, pressure: float, tolerance: float, max_steps: int,
                 pause: Callable[[bool], bool] | None = None) -> tuple[int, float]:
        """Minimise the enthalpy at fixed pressure, from rest, until converged or out of steps.

        A minimisation restored from a checkpoint in progress (`restore`) continues where it
        paused.

        Parameters
        ----------
        pressure : float
            Target pressure p*, in units of ε / (mean diameter)^d.
        tolerance : float
            Converged when max_i |F_i| ≤ tolerance × the mean force of the overlapping pairs
            (or the round-off floor of the forces, `ROUNDOFF_FORCE` × eps × L) and
            |p − p*| ≤ tolerance × p*.
        max_steps : int
            Steps (FIRE steps, L-BFGS force evaluations, Newton solves) allowed to this
            minimisation.
        pause : callable, optional
            Called as ``pause(stopped)`` after every list rebuild and every `PAUSE_STEPS`
            steps, where the state is complete (`state`); `stopped` is True when the steps
            ran out, and the minimisation then returns as it stands. When it returns True
            the minimisation returns as it stands too, with the code `HALTED`.

        Returns
        -------
        code : int
            `_fire.CONVERGED`, `_fire.OUT_OF_STEPS` or `HALTED`.
        pressure : float
            Pressure at the end.
        """
        if not self.method.size:
            self._begin(self.base if self.minimiser == "newton" else self.minimiser)
            self.rebuild()
            self.built, self.taken, self.built_at, self.drift = self.rebuilds, 0, 0, 0.0
        while True:
            kernel = self.kernel
            budget = max_steps - self.taken
            if self.minimiser == "newton":
                limit = NEWTON_PHASE_SOLVES if kernel == "newton" else NEWTON_AFTER_STEPS
                budget = min(budget, limit - int(self.method[PHASE_TAKEN]))
            code, steps, reached, drift = self._run(
                pressure, tolerance, min(budget, NEWTON_PAUSE_STEPS if kernel == "newton"
                                         else PAUSE_STEPS))
            self.taken += steps
            if kernel == "newton":
                self.solves += steps
            if steps:
                self.drift = drift
            state = self.method[PHASE_STATE:] if self.minimiser == "newton" else self.method
            self.scale = float(np.exp(state[LOG_SCALE_SLOT[kernel]]))
            if code == _fire.CONVERGED:
                break
            stopped = code == _fire.OUT_OF_STEPS and self.taken >= max_steps
            if self.minimiser == "newton" and not stopped:
                self.method[PHASE_TAKEN] += steps
                if self.method[PHASE_TAKEN] >= limit:     # the phase is over: the other one
                    self._begin("newton" if kernel == self.base else self.base)
            if code == _fire.REBUILD:
                self._adapt_skin()
                self.rebuild()
            if pause is not None and pause(stopped) and not stopped:
                code, stopped = HALTED, True
            if stopped:
                break
        self.steps += self.taken
        if self.rebuilds == self.built:
            self.skin = min(self.max_skin, max(SKIN_MIN, SKIN_DRIFT_FACTOR * self.drift))
        self.method = np.empty(0)
        self.memory_x = np.empty((2, 0, self.x.size))
        self.memory_u = np.empty((4, 0))
        return code, reached

    def _run(self, pressure: float, tolerance: float,
             max_steps: int) -> tuple[int, int, float, float]:
        """One call of the kernel (`_fire.fire_run`, `_lbfgs.lbfgs_run` or
        `_newton.newton_run`) on its state (a view into `method`)."""
        kernel = self.kernel
        state = self.method[PHASE_STATE:] if self.minimiser == "newton" else self.method
        if kernel == "newton":
            return _newton.newton_run(
                self.x, self.f, self.s, self.box, *self.lists[:2], self.x_built, self.skin,
                self.scale_built, state, tolerance, self.force_floor, pressure,
                max_steps, self.periodic, self.circle)
        if kernel == "lbfgs":
            return _lbfgs.lbfgs_run(
                self.x, self.f, self.s, self.box, *self.lists, self.x_built, self.skin,
                self.scale_built, state, self.memory_x, self.memory_u, tolerance,
                self.force_floor, pressure, max_steps, self.periodic, self.circle)
        return _fire.fire_run(
            self.x, self.v, self.f, self.s, self.box, *self.lists, self.x_built,
            self.skin, self.scale_built, state, DT_MAX_FACTOR * self.dt0,
            _fire.DT_MIN_FRACTION * self.dt0, tolerance, self.force_floor, pressure,
            max_steps, self.periodic, self.circle)

    def pairs_below(self, gap: float,
                    rebuild: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pairs with relative gap |r|/σ − 1 below `gap`, in original particle indices,
        i < j, sorted lexicographically, with their gaps. ``rebuild=False`` reads the
        current neighbour lists (valid at a pause of a minimisation, and only for gaps
        within the skin) and leaves the list rebuilds of the minimisation as they are."""
        if rebuild:
            self.rebuild()
        i, j, gaps = _fire.contact_pairs(self.x, self.s, self.scale, self.box, *self.lists[:2],
                                         gap, self.periodic)
        i, j = self.ids[i], self.ids[j]
        i, j = np.minimum(i, j), np.maximum(i, j)
        order = np.lexsort((j, i))
        return i[order], j[order], gaps[order]

    def walls_below(self, gap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Particle–wall pairs with relative gap δ/(σ_i/2) − 1 below `gap` (`_checks.wall_gaps`;
        walls 2μ at 0, 2μ + 1 at L_μ, 2d the cylinder), in original particle indices, sorted
        by particle then wall, with their gaps; empty in a periodic box."""
        particle, wall, gaps = wall_gaps(self.x, self.scale * self.s, self.box, self.periodic,
                                         self.cylinder)
        below = gaps < gap
        particle, wall, gaps = self.ids[particle[below]], wall[below], gaps[below]
        order = np.lexsort((wall, particle))
        return particle[order], wall[order], gaps[order]

    def overlap_network(self, rebuild: bool = True
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pairs overlapping by more than `TOUCH` (`pairs_below`)."""
        return self.pairs_below(-TOUCH, rebuild)

    def wall_overlaps(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Particle–wall pairs overlapping by more than `TOUCH` (`walls_below`)."""
        return self.walls_below(-TOUCH)

    def isostatic_count(self, stable: int) -> int:
        """Contacts (pairs and walls) of an isostatic network of `stable` particles:
        d N_s + 1 − (zero modes: the periodic axes, and the rotation about a cylinder's
        axis), which is d (N_s − 1) + 1 in a periodic box."""
        return (self.x.shape[1] * stable + 1 - int(np.count_nonzero(self.periodic))
                - (1 if self.cylinder else 0))

    def stable_network(self, rebuild: bool = True) -> tuple[np.ndarray, int]:
        """The overlap network without rattlers (recursively; a wall contact counts for its
        particle), shape (M + K, 2), sorted, and the number of particles it holds. Its M
        pairs come first, then its K wall contacts as (particle, N + wall). ``rebuild``:
        as in `pairs_below`."""
        n = self.x.shape[0]
        i, j, _ = self.overlap_network(rebuild)
        particle, wall, _ = self.wall_overlaps()
        rattlers, kept = remove_rattlers(n, self.x.shape[1], i, j, particle)
        on_wall = ~rattlers[particle]
        network = np.concatenate([np.stack([i[kept], j[kept]], axis=1),
                                  np.stack([particle[on_wall], n + wall[on_wall]], axis=1)])
        return network, int(np.count_nonzero(~rattlers))

    def positions(self) -> np.ndarray:
        """Positions in the original particle order, shape (N, d)."""
        out = np.empty_like(self.x)
        out[self.ids] = self.x
        return out


def pressure_ladder(first: float, final: float,
                    reduction: float = PRESSURE_REDUCTION) -> np.ndarray:
    """Pressures of the minimisations, geometric from `first` down to `final` in the fewest
    equal factors no smaller than `reduction` (`final` alone if it is not below `first`)."""
    if final >= first:
        return np.array([final])
    steps = int(np.ceil(np.log(first / final) / np.log(1.0 / reduction)))
    ladder = first * (final / first) ** (np.arange(steps + 1) / steps)
    ladder[-1] = final
    return ladder


def _check_box(box: np.ndarray, nominal: np.ndarray, skin: float, phi_start: float,
               densest: float, periodic: np.ndarray) -> None:
    """ValueError if the list reach (largest diameter + skin) may not stay below half a
    periodic side of the box, or the largest diameter not below a side between walls.

    The diameters grow by (φ/φ_start)^(1/d) when the quench compresses; `densest` bounds φ.
    """
    growth = max(1.0, densest / phi_start) ** (1.0 / box.shape[0])
    largest = float(nominal.max()) * growth
    reach = largest + skin
    periodic_sides = box[periodic]
    if periodic_sides.size and reach >= 0.5 * float(periodic_sides.min()):
        raise ValueError(f"too few particles: the box side {periodic_sides.min():.3g} (mean "
                         f"diameters) is not above twice the largest diameter plus the skin "
                         f"({reach:.3g} at φ = {max(densest, phi_start):.3g}); use more "
                         f"particles")
    walled_sides = box[~periodic]
    if walled_sides.size and largest >= float(walled_sides.min()):
        raise ValueError(f"too few particles: the walls are {walled_sides.min():.3g} mean "
                         f"diameters apart, not wider than the largest diameter ({largest:.3g} "
                         f"at φ = {max(densest, phi_start):.3g}); use more particles")


def default_target_pressure(n: int, d: int, boundaries: Boundaries | None = None) -> float:
    """The `target_pressure` that `soft_quench` takes when none is given (ε/⟨σ⟩^d).

    `EARLY_TARGET_PRESSURE` (1e-6) for periodic packings of at most `EARLY_STOP_MAX_N`
    (4096) particles in d = 3 and 4, `LATE_TARGET_PRESSURE` (1e-7) otherwise (larger
    packings, d = 2 and d ≥ 5, containers): where stopping a decade earlier was measured to
    save time and `calippso.jam` still certified every quench with no LP
    (docs/notes/soft-quench-protocol.md).

    Parameters
    ----------
    n : int
        Number of particles.
    d : int
        Dimension.
    boundaries : Boundaries, optional
        The container; None: periodic along every axis.
    """
    periodic = boundaries is None or boundaries.is_periodic
    early = periodic and n <= EARLY_STOP_MAX_N and d in EARLY_STOP_DIMENSIONS
    return EARLY_TARGET_PRESSURE if early else LATE_TARGET_PRESSURE


def soft_quench(diameters, d: int, *, seed: int = 0, phi_start: float | None = None,
                target_pressure: float | None = None, force_tolerance: float = 1e-6,
                progress: bool = False, skin: float = 0.2, max_steps: int = 50_000_000,
                checkpoint: str | os.PathLike | None = None,
                checkpoint_every: float = 60.0, minimiser: str = "auto",
                boundaries: Boundaries | None = None,
                settle: Callable[[GenerationResult], str | None] | None = None,
                settle_excess: int = SETTLE_EXCESS) -> GenerationResult:
    """Quench harmonic soft spheres to a vanishing pressure, then shrink them to hard contact.

    The route of O'Hern, Silbert, Liu & Nagel (2003) into a hard-sphere jamming basin, with
    the pressure controlled directly: uniform random centres in a cubic box at `phi_start`,
    with the harmonic repulsion V = ε/2 (1 − r/σ)² for r < σ, are brought to enthalpy minima
    H = E + p* V by FIRE 2.0 (Δt_max = 5 Δt0) or L-BFGS (`minimiser`), the diameter scale
    being one more degree of freedom. The pressures p* go down from 1e-2 in equal factors of
    at most 10 to half of `target_pressure`. At fixed pressure a minimum always exists, so
    no step can unjam (at fixed density, decompression steps near p → 0 unjammed and slid
    towards zero energy for up to 4e5 FIRE steps each). Minima are converged to forces of
    1e-4 of the mean pair force; the last one then decade by decade until its overlap
    network (rattlers removed) is the same two decades in a row and not hypostatic, or
    `force_tolerance` is reached. Finally all diameters shrink by one factor until the most
    overlapping pair has a gap of 1e-12: the overlap network becomes the contact network of
    a nearby hard-sphere jamming point, returned as `contacts` for
    ``calippso.jam(packing, network=contacts)``.

    Parameters
    ----------
    diameters : array_like, shape (N,)
        Diameters σ_i > 0; only their ratios matter (the result has exactly these diameters,
        in a box sized accordingly).
    d : int
        Dimension (≥ 2).
    seed : int
        Seed of the random centres.
    phi_start : float, optional
        Packing fraction of the random centres, in (0, 1); default 1.12 × a typical jamming
        density (0.94, 0.69, 0.53, 0.35 in d = 2, 3, 4, 5). The first minimisation moves it
        to where the pressure is 1e-2.
    target_pressure : float, optional
        The last minimum has half this pressure, in units of ε / (mean diameter)^d. The
        largest overlap is then ~5 × the target (d = 3), and the contact gaps after the
        shrink lie between 1e-12 and that overlap. Default: `default_target_pressure` (1e-6
        for periodic packings of up to 4096 particles in d = 3 and 4, 1e-7 otherwise).
    force_tolerance : float
        Tightest convergence of the last minimisation: max_i |F_i| at or below this × the
        mean force of the overlapping pairs (or the round-off floor of the forces,
        50 × machine epsilon × the box side in mean diameters).
    progress : bool
        Show a tqdm bar (−log10 p); quiet by default.
    skin : float
        Largest Verlet skin in mean diameters. Below it the skin follows the rebuild rate
        (the cost of rebuilding the lists against that of listing non-interacting pairs),
        and once the particles settle their drift per minimisation (down to 0.02).
    max_steps : int
        Limit on the steps of the whole run (FIRE steps, L-BFGS force evaluations or Newton
        solves; an L-BFGS line search in progress finishes). A run stopped by it and called again with
        a larger limit and the same checkpoint continues where it stopped.
    checkpoint : str or PathLike, optional
        File (``.npz``) holding the state of the run (`generators.checkpoint`). It is written
        atomically at most every `checkpoint_every` seconds (at a list rebuild, every 1000
        steps or every 10 Newton solves), when the steps run out, and at the end. A call
        with the same inputs resumes from it and returns the result of the uninterrupted run, bit for bit; a
        finished run returns from it at once. `max_steps` may differ between the calls.
    checkpoint_every : float
        Smallest wall time in seconds between two checkpoint writes (0: at every pause).
    minimiser : {"auto", "fire", "lbfgs", "newton"}
        The minimiser of the enthalpy: FIRE 2.0, or L-BFGS with a Wolfe line search
        (`steps` then counts force evaluations); "auto" takes L-BFGS in d ≥ 4 and FIRE in
        d = 2, 3. "newton": within each minimisation, the "auto" minimiser for 20,000 steps,
        then a damped Newton on the sparse Gauss–Newton Hessian (`generators._newton`) for up
        to 40 solves, and so on in turn (`steps` counts both, ``extra["newton_solves"]`` the
        solves). All stop on the same convergence test.
    boundaries : calippso.Boundaries, optional
        The container: periodic along every axis (None, the default), flat walls at 0 and
        L along some axes (`Boundaries.walls`), or a cylinder (`Boundaries.cylinder`). A
        particle closer to a wall than its radius σ_i/2 overlaps it by σ_i/2 − δ and has the
        energy of a pair with that overlap; its virial (force × δ) is in the pressure. In a
        cylinder of diameter L, δ = L/2 − ρ_i (ρ_i: the centre's distance from the
        cylinder's axis), the force points to the axis, and the pressure is over the
        cylinder's volume. The compression grows the diameters in a fixed box, which is the
        box shrinking affinely, walls and all. Along a walled or a cylinder's axis there is
        no minimum image and no wrap.

    settle : callable, optional
        ``settle(reached)`` after every converged rung of the ladder but the last, and at
        every pause of a minimisation (every 1000 minimiser steps, every list rebuild)
        where the overlap network without rattlers has not changed since the previous
        pause, each network once, when that network is neither hypostatic nor more than
        `settle_excess` contacts beyond isostatic; `reached` is the state shrunk to hard
        contact (a `GenerationResult` as returned, ``extra["rung"]`` its rung counted from
        1, ``extra["paused"]`` True within a minimisation). It returns None to go on, or
        the reason to end the quench there, in words (e.g. ``calippso.NetworkFirstSettle``: its
        network was certified with no LP). The result is then that state,
        ``extra["settled"]`` the reason, and the status says where it ended. A state
        handed to `settle` is shrunk from a fresh neighbour list, which changes the order
        of the floating-point sums, hence the minimiser's path, from a run without
        `settle`.
    settle_excess : int
        See `settle` (default `SETTLE_EXCESS`, 4).

    Returns
    -------
    GenerationResult
        `packing`: after the shrink, particles in the input order, diameters exactly the
        given ones. `contacts`: the overlap network before the shrink (pairs overlapping by
        more than 1e-12 σ) without rattlers, removed recursively (pairs i < j, int64,
        shape (M, 2), sorted lexicographically). `reduced_pressure` is nan (soft spheres
        have no hard-sphere pressure); `steps` counts FIRE steps (L-BFGS force
        evaluations, Newton solves); `history` holds one record per rung of the ladder
        (steps so far, φ before the shrink, pressure, nan).
        `extra`: ``pressure`` (final soft pressure, ε / (mean diameter)^d),
        ``target_pressure`` (the one used, given or default), ``minimisations``,
        ``fire_steps``, ``rebuilds`` (list rebuilds), ``phi_soft`` (φ before the shrink),
        ``shrink_factor`` (diameters were multiplied by it), ``max_overlap`` (largest
        relative overlap 1 − r/σ before the shrink),
        ``contact_overlaps`` (1 − r/σ of each pair of `contacts` before the shrink, shape
        (M,): the soft forces in units of ε/σ), ``near_contacts`` and ``near_gaps`` (the
        pairs that did not overlap but were closer than the largest overlap, shape (K, 2),
        i < j, sorted, and their relative gaps: the candidates to join the hard-sphere
        network, which is the limit p → 0 and can differ from `contacts` by a few pairs),
        ``isostaticity_gap`` (N_c − (d (N_s − 1) + 1) of `contacts`), ``stable``
        (N_s), ``overlap_correction`` (round-off shrink after an independent check, ~0),
        ``resumed`` (whether the run continued from a checkpoint; `wall_time` then adds up
        every call's time), ``minimiser`` ("fire", "lbfgs" or "newton": the one that ran), ``newton_solves``
        (the Newton solves among `steps`). Given `settle`: ``rungs`` (pressures of the
        ladder), ``rung`` (the rungs in `history`), ``settled`` (the reason `settle` gave,
        or None).
        With walls the packing carries the boundaries and lies inside its container;
        `contacts` holds particle pairs only (the stable particles are found with the wall
        contacts counted), and ``wall_contacts`` (particle, wall) pairs, walls 2μ at 0 and
        2μ + 1 at L_μ, 2d the cylinder (`calippso.geometry.walls.cylinder_wall`), shape (K, 2),
        sorted, with ``wall_overlaps`` (1 − δ/(σ_i/2) of each, shape (K,)), hold the stable
        particles' overlaps with the walls before the shrink; ``isostaticity_gap`` is then
        N_c − (d N_s + 1 − zero modes) with N_c counting both, the zero modes being the
        periodic axes and, in a cylinder, the rotation about its axis. Periodic: both
        empty.

    Raises
    ------
    ValueError
        On non-positive diameters, d < 2, phi_start outside (0, 1), non-positive pressure,
        tolerance or skin, a non-positive max_steps, too few particles for the box, or a
        checkpoint file that belongs to another run (one line naming the file).
    """
    wall = time.perf_counter()
    diameters = check_diameters(diameters)
    d = check_dimension(d)
    typical = phi_estimate(d)
    phi_start = check_phi(min(0.95, PHI_START_FACTOR * typical) if phi_start is None
                          else phi_start, "phi_start")
    boundaries = check_boundaries(boundaries, d, "soft_quench", BOUNDARY_KINDS)
    target_pressure, force_tolerance, skin, minimiser = check_quench_options(
        diameters.shape[0], d, boundaries, target_pressure, force_tolerance, skin, max_steps,
        minimiser)
    signature = {"diameters": digest(diameters), "d": d, "seed": int(seed),
                 "phi_start": phi_start, "target_pressure": target_pressure,
                 "force_tolerance": force_tolerance, "skin": skin, "minimiser": minimiser}
    if not boundaries.is_periodic:       # (absent from the checkpoints of periodic runs)
        signature["boundaries"] = str(boundaries)
    saver = Checkpoint(checkpoint, "soft_quench", signature,
                       every=check_positive(checkpoint_every, "checkpoint_every",
                                            allow_zero=True))
    mean = float(diameters.mean())
    start = poisson(diameters, d, phi=phi_start, seed=seed, boundaries=boundaries)
    box = start.box / mean
    nominal = diameters / mean
    _check_box(box, nominal, skin, phi_start, PHI_START_FACTOR * typical, boundaries.periodic)
    system = _SoftSpheres(start.positions / mean, nominal, box, skin, minimiser,
                          boundaries.periodic, boundaries.cylinder_axes)
    run = _Run(pressure_ladder(FIRST_PRESSURE, TARGET_AIM * target_pressure),
               force_tolerance, max_steps)
    if settle is None:
        return quench_and_shrink(system, run, saver, diameters, boundaries, target_pressure,
                                 progress, wall)

    def reached(system: _SoftSpheres, rung: int, pressure: float) -> GenerationResult:
        shrunk = _shrunk_result(system, diameters, mean, boundaries, run.rows, pressure,
                                target_pressure, f"quenched to pressure {pressure:.3g}, rung "
                                f"{rung} of {len(run.ladder)}", wall, False)
        shrunk.extra["rungs"] = run.ladder.copy()
        return shrunk

    asker = SettleAsker(settle, settle_excess, run, reached)
    result = quench_and_shrink(system, run, saver, diameters, boundaries, target_pressure,
                               progress, wall, watch=asker.at_pause, settled=asker.after_rung)
    result.extra.update(rungs=run.ladder.copy(), rung=len(run.rows),
                        settled=run.settled_by or asker.reason)
    return result


def check_quench_options(n: int, d: int, boundaries: Boundaries,
                         target_pressure: float | None, force_tolerance: float, skin: float,
                         max_steps: int, minimiser: str) -> tuple[float, float, float, str]:
    """The options of a quench checked (ValueError naming the bad one), the default target
    pressure filled in and minimiser="auto" resolved (see `soft_quench`).

    Returns
    -------
    (target_pressure, force_tolerance, skin, minimiser)
    """
    if target_pressure is None:
        target_pressure = default_target_pressure(n, d, boundaries)
    target_pressure = check_positive(target_pressure, "target_pressure")
    force_tolerance = check_positive(force_tolerance, "force_tolerance")
    skin = check_positive(skin, "skin")
    if int(max_steps) != max_steps or max_steps < 1:
        raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
    if minimiser not in MINIMISERS:
        raise ValueError(f"minimiser must be one of {', '.join(MINIMISERS)}, got {minimiser!r}")
    if minimiser == "auto":
        minimiser = "lbfgs" if d >= LBFGS_FROM_DIMENSION else "fire"
    return target_pressure, force_tolerance, skin, minimiser


class SettleAsker:
    """When a quench or a relaxation asks its caller's `settle` whether the state reached
    will do, and what it hands it: the state shrunk to hard contact, after every rung but
    the last (`after_rung`), and at a pause of a minimisation where the overlap network
    without rattlers is the same as at the previous pause (`at_pause`); each network once,
    and only one within `excess` contacts of isostatic, not hypostatic.

    Parameters
    ----------
    settle : callable
        ``settle(reached)``: None to go on, or the reason to end the run there, in words.
    excess : int
        Largest number of contacts beyond the isostatic count of a network asked about.
    run : _Run
        The run's ladder and history.
    reached : callable
        ``reached(system, rung, pressure)``: the state shrunk to hard contact, as the
        caller returns its results (`rung` counted from 1).

    Attributes
    ----------
    reason : str or None
        What `settle` answered at a pause, if it ended the run there.
    """

    def __init__(self, settle: Callable[[GenerationResult], str | None], excess: int,
                 run: "_Run",
                 reached: Callable[["_SoftSpheres", int, float], GenerationResult]) -> None:
        if int(excess) != excess or excess < 0:
            raise ValueError(f"settle_excess must be a non-negative integer, got {excess!r}")
        self.settle, self.excess, self.run, self.reached = settle, int(excess), run, reached
        self.previous: np.ndarray | None = None
        self.asked: set[bytes] = set()
        self.reason: str | None = None

    def after_rung(self, system: "_SoftSpheres") -> str | None:
        """`settle`'s answer at the end of the rung just finished (None without asking
        when its network is not one to ask about)."""
        self.previous = None
        network, stable = system.stable_network()
        if not self._new_and_near(system, network, stable):
            return None
        return self._ask(system, self.run.rung, self.run.pressure, False)

    def at_pause(self, system: "_SoftSpheres") -> str | None:
        """`settle`'s answer at a pause whose network has not changed since the last one
        (None without asking otherwise). The network is read from the minimisation's
        neighbour lists, without a rebuild."""
        network, stable = system.stable_network(rebuild=False)
        same = self.previous is not None and np.array_equal(network, self.previous)
        self.previous = network
        if not same or not self._new_and_near(system, network, stable):
            return None
        self.reason = self._ask(system, self.run.rung + 1,
                                float(self.run.ladder[self.run.rung]), True)
        return self.reason

    def _new_and_near(self, system: "_SoftSpheres", network: np.ndarray,
                      stable: int) -> bool:
        """`network` (of `stable` particles) was not asked about yet, and lies within
        `excess` contacts of isostatic, not below, and holds some particle; it counts as
        asked from now on."""
        key = network.tobytes()
        if key in self.asked or stable == 0 \
                or not 0 <= len(network) - system.isostatic_count(stable) <= self.excess:
            return False
        self.asked.add(key)
        return True

    def _ask(self, system: "_SoftSpheres", rung: int, pressure: float,
             paused: bool) -> str | None:
        reached = self.reached(system, rung, pressure)
        reached.extra.update(rung=rung, paused=paused, settled=None)
        return self.settle(reached)


def quench_and_shrink(system: _SoftSpheres, run: "_Run", saver: Checkpoint,
                      diameters: np.ndarray, boundaries: Boundaries, target_pressure: float,
                      progress: bool, wall: float, box: np.ndarray | None = None,
                      watch: Callable[[_SoftSpheres], str | None] | None = None,
                      settled: Callable[[_SoftSpheres], str | None] | None = None
                      ) -> GenerationResult:
    """Walk `system` down the ladder of `run` (resuming from `saver`'s checkpoint, saving
    to it), then shrink it to hard contact (`_shrunk_result`).

    Parameters
    ----------
    system : _SoftSpheres
        The soft spheres at their start (lengths in mean diameters).
    run : _Run
        The ladder, tolerances and step limit.
    saver : Checkpoint
        Where the run's state is saved (disabled without a file).
    diameters : ndarray, shape (N,)
        The caller's diameters (length units).
    boundaries : Boundaries
    target_pressure : float
        The target the run was given (for the status and ``extra``).
    progress : bool
        Show a tqdm bar.
    wall : float
        `time.perf_counter()` at the call.
    box : ndarray, shape (d,), optional
        Keep this box (the caller's units) and scale the diameters by one factor instead
        (`generators.relax`); None: keep the diameters and size the box.
    watch : callable, optional
        ``watch(system)`` at every pause of a minimisation (`_SoftSpheres.minimise`):
        None to go on, or the reason to stop the quench there, in words. A stopped quench
        is saved to the checkpoint and shrunk as it stands; its status gives the reason.
    settled : callable, optional
        ``settled(system)`` after every converged rung but the last (`_Run.quench`): None
        to go on down the ladder, or the reason to end the quench there, in words (the
        state is shrunk as it stands; the status gives the reason).
    """
    earlier_wall = 0.0
    halted_by: list[str] = []
    saved = saver.load()
    if saved is not None:
        system.restore(saved)
        run.restore(saved)
        earlier_wall = float(saved["wall_time"])

    def pause(stopped: bool) -> bool:
        reason = None if stopped or watch is None else watch(system)
        if reason is not None:
            halted_by.append(reason)
        if saver.enabled and (stopped or reason is not None or saver.due()):
            saver.save({**system.state(), **run.state(),
                        "wall_time": earlier_wall + time.perf_counter() - wall})
        return reason is not None

    bar = Progress(progress, -np.log10(run.ladder[-1]), "soft quench -log10(p)")
    try:
        code, pressure = run.quench(system, pause, bar, settled)
    finally:
        bar.close()
    if code == _fire.OUT_OF_STEPS:
        status = f"stopped at max_steps = {run.max_steps} (pressure {pressure:.3g})"
    elif code == SETTLED:
        status = f"ended early at pressure {pressure:.3g}: {run.settled_by}"
    elif code == HALTED:
        status = f"stopped at pressure {pressure:.3g}: {halted_by[-1]}"
    else:
        status = f"converged at pressure {pressure:.3g} <= target {target_pressure:.3g}"
        pause(True)
    return _shrunk_result(system, diameters, float(diameters.mean()), boundaries, run.rows,
                          pressure, target_pressure, status, wall - earlier_wall,
                          saved is not None, box)


@dataclass
class _Run:
    """Where a quench stands on its ladder of pressures, and its history.

    Attributes
    ----------
    ladder : ndarray
        Pressures of the minimisations (`pressure_ladder`).
    force_tolerance : float
        Tightest convergence of the last minimisation (see `soft_quench`).
    max_steps : int
        Limit on the steps of the whole run.
    rung : int
        Index in `ladder` of the minimisation in progress (len(ladder) once all are done).
    round : int
        0: the rung's minimisation to `INTERMEDIATE_TOLERANCE`; k ≥ 1: the k-th tightening
        round of the last rung, each converged ten times tighter.
    previous : ndarray of int64, shape (M, 2)
        The stable overlap network after the last round (tightening only).
    rows : list of tuple
        One history row per finished rung: (steps so far, φ, pressure, nan).
    pressure : float
        Pressure at the end of the last minimisation.
    settled_by : str or None
        Why the `settled` test of `quench` ended the quench, if it did.
    """

    ladder: np.ndarray
    force_tolerance: float
    max_steps: int
    rung: int = 0
    round: int = 0
    previous: np.ndarray = field(default_factory=lambda: np.empty((0, 2), dtype=np.int64))
    rows: list = field(default_factory=list)
    pressure: float = float("nan")
    settled_by: str | None = None

    def state(self) -> dict:
        """Where the run stands, for a checkpoint."""
        return {"run_rung": self.rung, "run_round": self.round, "run_previous": self.previous,
                "run_pressure": self.pressure, "history": make_history(self.rows)}

    def restore(self, saved: dict) -> None:
        """Continue from a `state()` dict (as read back from a checkpoint)."""
        self.rung, self.round = int(saved["run_rung"]), int(saved["run_round"])
        self.previous = np.array(saved["run_previous"], dtype=np.int64).reshape(-1, 2)
        self.pressure = float(saved["run_pressure"])
        self.rows = [tuple(row) for row in saved["history"].tolist()]

    def tolerance(self) -> float:
        """Force tolerance of the current round: `INTERMEDIATE_TOLERANCE` divided by ten per
        round, not below `force_tolerance`."""
        tolerance = INTERMEDIATE_TOLERANCE
        for _ in range(self.round):
            tolerance = max(tolerance / 10.0, self.force_tolerance)
        return tolerance

    def quench(self, system: _SoftSpheres, pause: Callable[[bool], bool],
               bar: Progress,
               settled: Callable[[_SoftSpheres], str | None] | None = None
               ) -> tuple[int, float]:
        """Run the remaining minimisations: every rung of the ladder, the last one tightened,
        unless `settled` (called after every converged rung but the last) gives a reason to
        end there (kept in `settled_by`).

        Returns
        -------
        code : int
            `_fire.CONVERGED`, `_fire.OUT_OF_STEPS` when `max_steps` ran out, `HALTED`
            when `pause` stopped a minimisation, or `SETTLED` when `settled` ended the
            quench after a rung.
        pressure : float
            Pressure at the end.
        """
        while self.rung < len(self.ladder):
            code, self.pressure = system.minimise(self.ladder[self.rung], self.tolerance(),
                                                  self.max_steps - system.steps, pause)
            if code == _fire.CONVERGED and self.rung == len(self.ladder) - 1 \
                    and self._tighten_again(system):
                continue
            self.rows.append((system.steps, system.phi, self.pressure, np.nan))
            bar.update(-np.log10(self.pressure), phi=f"{system.phi:.6f}",
                       p=f"{self.pressure:.3g}")
            if code != _fire.CONVERGED:     # (its checkpoint holds the minimisation)
                return code, self.pressure
            self.rung, self.round = self.rung + 1, 0
            if settled is not None and self.rung < len(self.ladder):
                self.settled_by = settled(system)
                if self.settled_by is not None:
                    return SETTLED, self.pressure
        return _fire.CONVERGED, self.pressure

    def _tighten_again(self, system: _SoftSpheres) -> bool:
        """After a converged minimisation of the last rung: whether to converge it once more.

        The tolerance drops tenfold each round, down to `force_tolerance`; the tightening
        stops early once two rounds in a row leave the same overlap network without
        rattlers (wall contacts included), and that network is not hypostatic (in practice
        below 1e-5 of the mean force, docs/notes/soft-quench-protocol.md).
        """
        network, stable = system.stable_network()
        if (self.round > 0 and np.array_equal(network, self.previous)
                and len(network) >= system.isostatic_count(stable)):
            return False
        if self.tolerance() <= self.force_tolerance:
            return False
        self.previous, self.round = network, self.round + 1
        return True


def _shrunk_result(system: _SoftSpheres, diameters: np.ndarray, mean: float,
                   boundaries: Boundaries, rows: list, pressure: float, target_pressure: float,
                   status: str, started: float, resumed: bool,
                   box: np.ndarray | None = None) -> GenerationResult:
    """Shrink the overlaps (with particles and walls) away, find the network without
    rattlers, build the result (`target_pressure`: the one the run was given). The
    packing has exactly `diameters` in a box sized accordingly, or, given `box`, that box
    and `diameters` times one factor."""
    n, d = system.x.shape
    i, j, gaps = system.overlap_network()
    particle, wall, wall_gap = system.wall_overlaps()
    rattlers, kept = remove_rattlers(n, d, i, j, particle)
    on_wall = ~rattlers[particle]
    contacts = np.stack([i[kept], j[kept]], axis=1).astype(np.int64)
    wall_contacts = np.stack([particle[on_wall], wall[on_wall]], axis=1).astype(np.int64)
    stable = int(n - np.count_nonzero(rattlers))
    worst = float(np.concatenate([gaps, wall_gap]).min()) if gaps.size + wall_gap.size else 0.0
    shrink = (1.0 + min(worst, 0.0)) / (1.0 + SHRINK_GAP)
    near_i, near_j, near_gaps = system.pairs_below(-worst)
    near = near_gaps >= -TOUCH
    # Lengths back in the caller's units: the diameters exactly the given ones, or the box.
    if box is None:
        factor = mean / (system.scale * shrink)
        positions, box, sizes = system.positions() * factor, system.box * factor, diameters
    else:
        positions, sizes = system.positions() * mean, diameters * (system.scale * shrink)
    sizes, correction = remove_roundoff_overlap(positions, sizes, box, boundaries.periodic,
                                                boundaries.cylinder_axes)
    packing = Packing(positions, sizes, box, boundaries).wrapped()
    return GenerationResult(
        packing=packing, reduced_pressure=float("nan"), steps=system.steps,
        wall_time=time.perf_counter() - started, history=make_history(rows), status=status,
        contacts=contacts,
        extra={"pressure": float(pressure), "target_pressure": target_pressure,
               "minimisations": len(rows), "fire_steps": system.steps,
               "rebuilds": system.rebuilds, "phi_soft": system.phi, "shrink_factor": shrink,
               "max_overlap": -worst, "contact_overlaps": -gaps[kept],
               "near_contacts": np.stack([near_i[near], near_j[near]], axis=1),
               "near_gaps": near_gaps[near], "stable": stable,
               "wall_contacts": wall_contacts, "wall_overlaps": -wall_gap[on_wall],
               "isostaticity_gap": (int(contacts.shape[0] + wall_contacts.shape[0])
                                    - system.isostatic_count(stable)),
               "overlap_correction": correction, "resumed": resumed,
               "minimiser": system.minimiser, "newton_solves": system.solves})
