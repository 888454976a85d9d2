"""Closest jammed configuration: the modified LS (MLS) protocol of Baranau & Tallarek (2014)."""

from __future__ import annotations

import time

import numpy as np

from calippso.geometry.boundaries import CYLINDER, PERIODIC, WALLS, Boundaries
from calippso.geometry.packing import Packing

from ._checks import check_positive
from ._progress import Progress
from .checkpoint import Checkpoint, digest
from .initial import start_of
from .ls import GrowingSpheres
from .result import GenerationResult, make_history

__all__ = ["closest_jamming"]

#: Packing fraction of the Poisson centres MLS starts from when given diameters (the
#: Baranau–Tallarek protocol's random start).
START_PHI = 0.3
#: The boundary kinds `closest_jamming` handles (those of `GrowingSpheres`).
BOUNDARY_KINDS = (PERIODIC, WALLS, CYLINDER)


def closest_jamming(diameters=None, d: int | None = None, *, seed: int = 0,
                    start: Packing | None = None, phi_start: float = START_PHI,
                    initial_rate: float = 10.0, final_rate: float = 1e-4,
                    rate_decrease: float = 2.0, max_pressure: float = 1e12,
                    temperature: float = 0.2, pressure_window: int = 20,
                    max_equilibrations: int = 50, max_windows_per_rate: int = 10_000,
                    max_collisions: int | None = None, progress: bool = False, skin: float = 0.1,
                    checkpoint=None, checkpoint_every: float = 60.0,
                    boundaries: Boundaries | None = None) -> GenerationResult:
    """Jam a start while staying in its basin: fast growth first, ever slower near jamming.

    The protocol, in event-driven MD (`GrowingSpheres`, as in LS):

    1. grow at the current rate, measuring the reduced pressure over windows of
       `pressure_window` collisions per particle, until p > `max_pressure`;
    2. if the rate is already `final_rate`, the packing is jammed: stop;
    3. otherwise stop growing and equilibrate (rate 0) window by window until p falls below
       `max_pressure`, then divide the rate by `rate_decrease` (not below `final_rate`) and go
       back to 1; if p stays above `max_pressure` for `max_equilibrations` windows the
       packing is jammed: stop.
    4. if p stays below `max_pressure` for `max_windows_per_rate` growth windows at one rate,
       the pressure has levelled off: the packing rearranges as fast as it grows. Lower the
       rate as in 3 (no equilibration is needed); at the final rate, stop with a status
       that says so. The published protocol (steps 1–3) does not end in this case.

    Parameters
    ----------
    diameters : array_like, shape (N,), optional
        Diameters (length units), given uniform random (Poisson) centres at packing fraction
        `phi_start`. Not needed with `start`.
    d : int, optional
        Dimension (≥ 2); required with diameters.
    seed : int
        Seed of the Poisson centres (if any) and of the velocities.
    start : Packing, optional
        The configuration whose closest jamming point is sought, instead of Poisson centres.
        An overlapping start is first scaled down to no overlap.
    phi_start : float
        Packing fraction of the Poisson centres made from `diameters`.
    initial_rate, final_rate : float
        Growth rates dσ/dt (nominal diameter 1, mass 1, kT = `temperature`) at the start and
        at the end.
    rate_decrease : float
        Factor (> 1) by which the rate is divided after each successful equilibration.
    max_pressure : float
        Reduced pressure p = βP/ρ taken as "jammed".
    temperature : float
        kT of the velocity rescaling.
    pressure_window : int
        Collisions per particle per pressure measurement.
    max_equilibrations : int
        Windows of zero-rate equilibration after which a packing still above `max_pressure` is
        declared jammed.
    max_windows_per_rate : int
        Growth windows at one rate after which the rate is lowered although p stayed below
        `max_pressure` (step 4); 10,000 windows are 2e5 collisions per particle, about a
        whole run of the protocol from an FB or LS start.
    max_collisions : int, optional
        Safety limit on the number of collisions (default: none).
    progress : bool
        Show a tqdm bar (log10 p); quiet by default.
    skin : float
        Initial Verlet skin in mean diameters.
    checkpoint : str or PathLike, optional
        File (``.npz``) holding the state of the run, protocol phase included
        (`generators.checkpoint`). Written atomically at the end of a window at most every
        `checkpoint_every` seconds, and when the run ends. If the file exists the run resumes
        from it and continues bit-for-bit as the uninterrupted run would (a jammed run returns
        at once); only `max_collisions` may differ from the first call.
    checkpoint_every : float
        Smallest wall time in seconds between two checkpoint writes (0: every window).
    boundaries : calippso.Boundaries, optional
        The container of the Poisson centres made from `diameters`: periodic (None, the
        default), flat hard walls (`Boundaries.walls`) or a cylinder (`Boundaries.cylinder`),
        with wall collisions as in `lubachevsky_stillinger`. A `start` brings its own (this
        must then be None or the same).

    Returns
    -------
    GenerationResult
        `packing` in the start's box with grown diameters; history has one record per window
        (rate 0 during equilibration); `extra`: ``rate`` (last growth rate),
        ``equilibrations`` (windows at zero rate), ``rebuilds``, ``start_shrink``,
        ``overlap_correction``, ``time``, ``resumed`` (whether the run continued from a
        checkpoint; `wall_time` then adds up every call's time).

    Raises
    ------
    ValueError
        On non-positive rates, pressure or temperature, final_rate > initial_rate, a
        max_windows_per_rate that is not a positive integer, boundaries that contradict the
        start's, or a checkpoint file that belongs to another run.
    """
    wall = time.perf_counter()
    packing, _ = start_of(diameters, d, start, phi=phi_start, seed=seed,
                          boundaries=boundaries, generator="closest_jamming",
                          kinds=BOUNDARY_KINDS)
    rate = check_positive(initial_rate, "initial_rate")
    final_rate = check_positive(final_rate, "final_rate")
    if final_rate > rate:
        raise ValueError(f"final_rate {final_rate:g} exceeds initial_rate {rate:g}")
    if not rate_decrease > 1:
        raise ValueError(f"rate_decrease must be > 1, got {rate_decrease!r}")
    if isinstance(max_windows_per_rate, bool) or not (
            isinstance(max_windows_per_rate, (int, np.integer)) and max_windows_per_rate >= 1):
        raise ValueError(f"max_windows_per_rate must be a positive integer, got "
                         f"{max_windows_per_rate!r}")
    max_pressure = check_positive(max_pressure, "max_pressure")
    temperature = check_positive(temperature, "temperature")
    state = GrowingSpheres(packing, temperature, seed, check_positive(skin, "skin"))
    saver = Checkpoint(checkpoint, "closest_jamming", {
        "initial_rate": rate, "final_rate": final_rate, "rate_decrease": float(rate_decrease),
        "max_pressure": max_pressure, "temperature": temperature,
        "pressure_window": int(pressure_window), "max_equilibrations": int(max_equilibrations),
        "max_windows_per_rate": int(max_windows_per_rate),
        "seed": int(seed), "skin": float(skin),
        "start": digest(packing.positions, packing.diameters, packing.box),
        **({} if packing.boundaries.is_periodic else {"boundaries": str(packing.boundaries)})},
        every=check_positive(checkpoint_every, "checkpoint_every", allow_zero=True))
    limit = np.inf if max_collisions is None else int(max_collisions)
    window = pressure_window * packing.n
    rows: list[tuple] = []
    equilibrations = 0
    status = ""
    pressure = np.nan
    equilibrating = False   # phase: growing, or equilibrating at zero rate after p > max
    rounds = 0              # equilibration windows in the current phase
    growth_windows = 0      # growth windows at the current rate
    earlier_wall = 0.0
    saved = saver.load()
    if saved is not None:
        state.restore(saved)
        rows = [tuple(row) for row in saved["history"].tolist()]
        pressure = float(saved["pressure"])
        rate = float(saved["rate"])
        equilibrations = int(saved["equilibrations"])
        equilibrating = bool(saved["equilibrating"])
        rounds = int(saved["rounds"])
        growth_windows = int(saved["growth_windows"])
        earlier_wall = float(saved["wall_time"])
        if str(saved["status"]).startswith(("jammed", "levelled off")):
            status = str(saved["status"])

    def snapshot() -> dict:
        return {**state.state(), "history": make_history(rows), "pressure": pressure,
                "rate": rate, "equilibrations": equilibrations, "equilibrating": equilibrating,
                "rounds": rounds, "growth_windows": growth_windows, "status": status,
                "wall_time": earlier_wall + time.perf_counter() - wall}

    bar = Progress(progress, np.log10(max_pressure), "MLS log10(p)")

    def measure(growth: float) -> float:
        p = state.window(int(min(window, limit - state.collisions)), growth)
        rows.append((state.time, state.phi, p, growth))
        bar.update(np.log10(max(p, 1.0)), phi=f"{rows[-1][1]:.6f}", rate=f"{rate:.3g}")
        return p

    try:
        while not status:
            if rows and state.collisions >= limit:
                status = f"stopped at max_collisions = {limit}"
                break
            if not equilibrating:
                pressure = measure(rate)
                growth_windows += 1
                if state.collisions >= limit:
                    status = f"stopped at max_collisions = {limit}"
                elif pressure > max_pressure and rate <= final_rate:
                    status = f"jammed: p = {pressure:.3g} > {max_pressure:.3g} at the final rate"
                elif pressure > max_pressure:
                    equilibrating, rounds = True, 0
                elif growth_windows >= max_windows_per_rate and rate <= final_rate:
                    status = (f"levelled off: p stayed below {max_pressure:.3g} for "
                              f"{max_windows_per_rate} windows at the final rate (last p = "
                              f"{pressure:.3g}); the packing rearranges as fast as it grows")
                elif growth_windows >= max_windows_per_rate:
                    rate, growth_windows = max(rate / rate_decrease, final_rate), 0
            else:
                pressure = measure(0.0)
                equilibrations += 1
                rounds += 1
                if state.collisions >= limit:
                    status = f"stopped at max_collisions = {limit}"
                elif pressure < max_pressure:
                    rate = max(rate / rate_decrease, final_rate)
                    equilibrating, growth_windows = False, 0
            if equilibrating and rounds >= max_equilibrations and not status:
                status = (f"jammed: p = {pressure:.3g} stayed above {max_pressure:.3g} for "
                          f"{max_equilibrations} equilibration windows")
            saver.maybe_save(snapshot())
    finally:
        bar.close()
    saver.save(snapshot())
    result_packing, correction = state.packing()
    return GenerationResult(
        packing=result_packing, reduced_pressure=float(pressure), steps=state.collisions,
        wall_time=earlier_wall + time.perf_counter() - wall, history=make_history(rows),
        status=status,
        extra={"rate": rate, "equilibrations": equilibrations, "rebuilds": state.rebuilds,
               "start_shrink": state.start_shrink, "overlap_correction": correction,
               "time": state.time, "resumed": saved is not None})
