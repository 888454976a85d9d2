"""Lubachevsky–Stillinger compression: event-driven MD of hard spheres with growing diameters."""

from __future__ import annotations

import time

import numpy as np

from calippso.geometry.boundaries import CYLINDER, PERIODIC, WALLS, Boundaries
from calippso.geometry.neighbors import SAME_PLACE, check_no_duplicates, min_gap, shrink_to_margin
from calippso.geometry.packing import Packing

from ._checks import check_positive, remove_roundoff_overlap
from .checkpoint import Checkpoint, Resumable, digest
from ._progress import Progress
from .edmd import run_window
from .periodic import NO_CYLINDER
from .initial import start_of
from .result import GenerationResult, make_history

__all__ = ["lubachevsky_stillinger", "GrowingSpheres"]

#: The boundary kinds `lubachevsky_stillinger` handles.
BOUNDARY_KINDS = (PERIODIC, WALLS, CYLINDER)


class GrowingSpheres(Resumable):
    """The state of an event-driven run (used by LS and MLS).

    Parameters
    ----------
    packing : Packing
        Start, periodic, between flat walls or in a cylinder (inside it); if it overlaps, all
        diameters
        are first scaled down by one factor until the closest pair has a gap of 1e-9 σ
        (`calippso.geometry.neighbors.shrink_to_margin`; a Poisson start begins at a tiny density).
        Particles at the same place (closer than 1e-12 mean diameters) are refused with a
        ValueError that names them.
    temperature : float
        Target kT (mass 1).
    seed : int
        Seed of the Maxwell–Boltzmann velocities.
    skin : float
        Verlet skin in mean diameters.

    Attributes
    ----------
    x, v : ndarray, shape (N, d)
        Positions (wrapped along the periodic axes) and velocities.
    boundaries : Boundaries
        The start's container; `periodic` its periodic axes, shape (d,), bool, and
        `cylinder` its cylinder's axes (`edmd.run_window`; `periodic.NO_CYLINDER` without).
    nominal : ndarray, shape (N,)
        Nominal diameters s_i (mean 1); the diameters are s_i · scale.
    scale : float
        Current diameter scale a.
    time : float
        Simulated time so far.
    collisions, rebuilds : int
    """

    def __init__(self, packing: Packing, temperature: float, seed: int, skin: float) -> None:
        self.box = np.array(packing.box, dtype=np.float64)
        self.boundaries = packing.boundaries
        self.periodic = np.asarray(packing.periodic, dtype=np.bool_)
        self.cylinder = packing.boundaries.cylinder_axes or NO_CYLINDER
        self.x = np.array(packing.wrapped().positions, dtype=np.float64)
        mean = packing.mean_diameter
        check_no_duplicates(self.x, self.box, SAME_PLACE * mean, self.mask)
        self.nominal = np.asarray(packing.diameters, dtype=np.float64) / mean
        self.start_shrink = shrink_to_margin(min_gap(self.x, packing.diameters, self.box,
                                                     self.mask)[0])
        self.scale = mean * self.start_shrink
        self.temperature = temperature
        self.skin = skin
        n, d = self.x.shape
        v = np.random.default_rng(seed).standard_normal((n, d))
        v -= v.mean(axis=0)
        self.v = v * np.sqrt(temperature / np.mean(v * v))
        self.time = 0.0
        self.collisions = 0
        self.rebuilds = 0

    @property
    def phi(self) -> float:
        """Current packing fraction."""
        return Packing(self.x, self.nominal * self.scale, self.box, self.boundaries).phi

    def window(self, n_collisions: int, rate: float, temperature: float | None = None) -> float:
        """Run `n_collisions` collisions at growth rate `rate`; return the reduced pressure.

        The pressure is the collisional virial over the window,
        p = 1 + Σ_c |r_c| J_c / (d N ∫kT dt), velocities being rescaled to the target
        temperature every two collisions per particle.
        """
        n, d = self.x.shape
        kt = self.temperature if temperature is None else temperature
        elapsed, scale, virial, kt_time, collisions, rebuilds = run_window(
            self.x, self.v, self.nominal, self.box, self.scale, rate, kt, n_collisions, 2 * n,
            self.skin, np.inf, self.periodic, self.cylinder)
        self.scale = scale
        self.time += elapsed
        self.collisions += collisions
        self.rebuilds += rebuilds
        self._adapt_skin(collisions, rebuilds)
        return 1.0 + virial / (d * n * kt_time) if kt_time > 0 else np.inf

    def _adapt_skin(self, collisions: int, rebuilds: int) -> None:
        """Trade list rebuilds (O(N) each) against list length (work per collision).

        A rebuild costs about as much as N/2 collisions, and a thicker skin slows every
        collision; the skin grows (×1.25, up to 0.5 σ) while fewer than N collisions
        separate two rebuilds and shrinks (÷1.25, down to 0.05 σ) above 4 N. The dynamics do
        not depend on the skin, only the cost does.
        """
        n = self.x.shape[0]
        if rebuilds * n > collisions:
            self.skin = min(0.5, self.skin * 1.25)
        elif rebuilds * 4 * n < collisions:
            self.skin = max(0.05, self.skin / 1.25)

    #: Attributes (and their types) that, with the nominal diameters and the box, make up the
    #: whole state between two windows (each `run_window` call starts from them alone).
    STATE = {"x": np.float64, "v": np.float64, "scale": float, "skin": float, "time": float,
             "collisions": int, "rebuilds": int, "start_shrink": float}

    def packing(self) -> tuple[Packing, float]:
        """The current configuration, checked for overlaps with an independent KD-tree search.

        Round-off can leave a pair overlapping by ~1e-15 σ (the last collision leaves a pair
        exactly in contact); then all diameters are scaled down by that amount. Returns the
        packing and the relative correction applied (0 if none).
        """
        diameters, correction = remove_roundoff_overlap(self.x, self.nominal * self.scale,
                                                        self.box, self.mask,
                                                        self.boundaries.cylinder_axes)
        return Packing(self.x.copy(), diameters, self.box, self.boundaries), correction

    @property
    def mask(self) -> np.ndarray | None:
        """The periodic axes for the numpy checks, None when all are (their fast path)."""
        return None if self.boundaries.is_periodic else self.periodic


def current_rate(rows: list[tuple], growth_rate: float, final_growth_rate: float | None,
                 slowdown_pressure: float) -> float:
    """The growth rate of the next window: `final_growth_rate` once a window so far (history
    rows ``(time, phi, pressure, rate)``) reached `slowdown_pressure`. The switch is kept in
    the rows: the last one ran at the final rate or reached the pressure."""
    if final_growth_rate is not None and rows and (rows[-1][2] >= slowdown_pressure
                                                   or rows[-1][3] == final_growth_rate):
        return final_growth_rate
    return growth_rate


def lubachevsky_stillinger(diameters=None, d: int | None = None, *, seed: int = 0,
                           start: Packing | None = None, phi_start: float = 0.1,
                           growth_rate: float = 1e-2, target_pressure: float = 1e5,
                           temperature: float = 1.0, max_collisions: int | None = None,
                           progress: bool = False, pressure_window: int = 20,
                           skin: float = 0.1, final_growth_rate: float | None = None,
                           slowdown_pressure: float = 1e3, checkpoint=None,
                           checkpoint_every: float = 60.0,
                           boundaries: Boundaries | None = None) -> GenerationResult:
    """Compress hard spheres by Lubachevsky–Stillinger event-driven MD until a target pressure.

    Parameters
    ----------
    diameters : array_like, shape (N,), optional
        Diameters (length units). They get uniform random (Poisson) centres in a cubic box
        at packing fraction `phi_start`; any start that overlaps has all its diameters scaled
        down by one factor until no pair overlaps (from Poisson points the run therefore
        starts at a very low density, the "random start, fast LS" protocol; no force-biased
        stage is run). Not needed with `start`.
    d : int, optional
        Dimension (≥ 2); required with diameters.
    seed : int
        Seed of the Poisson centres (if any) and of the velocities.
    start : Packing, optional
        A configuration to compress instead (an LS continuation, or the precompression of
        `calippso.protocols.precompress`); overlaps are shrunk away as above.
    phi_start : float
        Packing fraction of the Poisson centres made from `diameters`.
    growth_rate : float
        dσ/dt for a particle of nominal diameter 1 (mass 1, time unit such that kT = 1 gives
        unit thermal speed per direction). Every diameter grows in proportion to its nominal
        value.
    target_pressure : float
        Stop once the reduced pressure p = βP/ρ measured over a window exceeds this.
    temperature : float
        kT; velocities are rescaled to it every two collisions per particle.
    max_collisions : int, optional
        Stop after this many collisions (default: no limit).
    progress : bool
        Show a tqdm bar (log10 p); quiet by default.
    pressure_window : int
        Collisions per particle over which the pressure is measured (one history record each).
    skin : float
        Initial Verlet-list skin, in mean diameters (adapted along the run to balance list
        rebuilds against list length; widened automatically at low density).
    final_growth_rate : float, optional
        If given, the growth rate from the first window whose pressure reaches
        `slowdown_pressure` on (it stays there even if the pressure dips again). A slow end
        lets the packing follow the collective rearrangements that open up near jamming; at
        a constant fast rate they freeze in, and the end state lies short of a jamming point
        (docs/howto/start-configurations.md, "A slow end"). Must not exceed `growth_rate`.
    slowdown_pressure : float
        Reduced pressure at which `final_growth_rate` takes over (ignored without it).
    checkpoint : str or PathLike, optional
        File (``.npz``) holding the state of the run (`generators.checkpoint`). It is written
        atomically at the end of a pressure window at most every `checkpoint_every` seconds,
        and when the run ends. If the file exists, the run resumes from it and continues
        bit-for-bit as the uninterrupted run would; `target_pressure` and `max_collisions`
        may differ from the first call (a finished run can be pushed further), every other
        input must be the same.
    checkpoint_every : float
        Smallest wall time in seconds between two checkpoint writes (0: every window).
    boundaries : calippso.Boundaries, optional
        The container of the Poisson centres made from `diameters`: periodic (None, the
        default), flat hard walls at 0 and L along some axes (`Boundaries.walls`) or a
        cylinder (`Boundaries.cylinder`). A `start` brings its own (this must then be None
        or the same). A sphere meets a wall when its centre is σ_i(t)/2 from it (for the
        cylinder: ρ_i = L/2 − σ_i(t)/2 from its axis) and is reflected elastically along the
        wall's normal, the wall's growth of the contact distance s_i γ/2 added as in a pair
        collision; the wall collisions add σ_i/2 × their impulse to the virial, so the
        pressure is that on the walls. No minimum image and no wrap along walled axes or
        the cylinder's.

    Returns
    -------
    GenerationResult
        `packing` has the final (grown) diameters in the start's box; with diameters as input
        the result is rescaled so that its diameters equal the given ones (the box follows).
        `extra`: ``rebuilds`` (neighbour-list rebuilds), ``start_shrink`` (factor applied to
        an overlapping start), ``overlap_correction`` (relative shrink for round-off overlaps
        at the end, ~1e-15 or 0), ``time`` (simulated time), ``resumed`` (whether the run
        continued from a checkpoint; `wall_time` then adds up every call's time). With
        walls or a cylinder the packing carries the boundaries, every centre inside them;
        `steps` counts pair and wall collisions.

    Raises
    ------
    ValueError
        On non-positive diameters, d < 2, non-positive rate / pressure / temperature,
        boundaries that contradict the start's, or a checkpoint file that belongs to another
        run.
    """
    wall = time.perf_counter()
    growth_rate = check_positive(growth_rate, "growth_rate")
    target_pressure = check_positive(target_pressure, "target_pressure")
    temperature = check_positive(temperature, "temperature")
    slowdown_pressure = check_positive(slowdown_pressure, "slowdown_pressure")
    if final_growth_rate is not None:
        final_growth_rate = check_positive(final_growth_rate, "final_growth_rate")
        if final_growth_rate > growth_rate:
            raise ValueError(f"final_growth_rate {final_growth_rate:g} exceeds growth_rate "
                             f"{growth_rate:g}")
    if pressure_window < 1:
        raise ValueError(f"pressure_window must be >= 1 collision per particle, got "
                         f"{pressure_window}")
    start, from_diameters = start_of(diameters, d, start, phi=phi_start, seed=seed,
                                     boundaries=boundaries, generator="lubachevsky_stillinger",
                                     kinds=BOUNDARY_KINDS)
    state = GrowingSpheres(start, temperature, seed, check_positive(skin, "skin"))
    signature = {"growth_rate": growth_rate, "temperature": temperature, "seed": int(seed),
                 "pressure_window": int(pressure_window), "skin": float(skin),
                 "start": digest(start.positions, start.diameters, start.box)}
    if not start.boundaries.is_periodic:     # (absent from the checkpoints of periodic runs)
        signature["boundaries"] = str(start.boundaries)
    if final_growth_rate is not None:      # (absent from the checkpoints of one-rate runs)
        signature.update(final_growth_rate=final_growth_rate,
                         slowdown_pressure=slowdown_pressure)
    saver = Checkpoint(checkpoint, "lubachevsky_stillinger", signature,
                       every=check_positive(checkpoint_every, "checkpoint_every", allow_zero=True))
    limit = np.inf if max_collisions is None else int(max_collisions)
    rows: list[tuple] = []
    pressure = np.nan
    earlier_wall = 0.0
    saved = saver.load()
    if saved is not None:
        state.restore(saved)
        rows = [tuple(row) for row in saved["history"].tolist()]
        pressure = float(saved["pressure"])
        earlier_wall = float(saved["wall_time"])

    def snapshot() -> dict:
        return {**state.state(), "history": make_history(rows), "pressure": pressure,
                "wall_time": earlier_wall + time.perf_counter() - wall}

    bar = Progress(progress, np.log10(target_pressure), "LS log10(p)")
    status = ""
    try:
        while True:
            if rows and pressure >= target_pressure:
                status = f"reached reduced pressure {pressure:.3g} >= target {target_pressure:.3g}"
                break
            if rows and state.collisions >= limit:
                status = f"stopped at max_collisions = {limit} (pressure {pressure:.3g})"
                break
            window = int(min(pressure_window * start.n, limit - state.collisions))
            rate = current_rate(rows, growth_rate, final_growth_rate, slowdown_pressure)
            pressure = state.window(window, rate)
            phi = state.phi
            rows.append((state.time, phi, pressure, rate))
            bar.update(np.log10(max(pressure, 1.0)), phi=f"{phi:.5f}", p=f"{pressure:.3g}")
            saver.maybe_save(snapshot())
    finally:
        bar.close()
    saver.save(snapshot())
    packing, correction = state.packing()
    if from_diameters:
        factor = float(np.mean(start.diameters)) / packing.mean_diameter
        packing = Packing(packing.positions * factor, packing.diameters * factor,
                          packing.box * factor, packing.boundaries).wrapped()
        # the rescaling can round a contact into a 1e-16 overlap again: remove it as well
        diameters, rescaled = remove_roundoff_overlap(packing.positions, packing.diameters,
                                                      packing.box, state.mask,
                                                      packing.boundaries.cylinder_axes)
        if rescaled:
            packing = Packing(packing.positions, diameters, packing.box, packing.boundaries)
            correction += rescaled
    return GenerationResult(
        packing=packing, reduced_pressure=float(pressure), steps=state.collisions,
        wall_time=earlier_wall + time.perf_counter() - wall, history=make_history(rows),
        status=status,
        extra={"rebuilds": state.rebuilds, "start_shrink": state.start_shrink,
               "overlap_correction": correction, "time": state.time,
               "resumed": saved is not None})
