"""Relax a given configuration as soft spheres: the soft quench started from the caller's
positions instead of random centres.

A packing made by LS or FB at a constant rate, or an MD snapshot, lies near but not at a
jamming point; the LP loop then slides it along collective channels for tens of LPs. Treated
as harmonic spheres at its own positions and diameters, inflated to a small pressure and
walked down the soft quench's pressure ladder, it settles into a nearby energy basin, whose
overlap network at p → 0⁺ is the contact network of a nearby hard-sphere jamming point
(O'Hern, Silbert, Liu & Nagel, PRE 68, 011306 (2003)).
"""

from __future__ import annotations

import os
import time
from typing import Callable

import numpy as np

from calippso.geometry.packing import Packing
from calippso.geometry.periodic import displacements, wrap

from ._checks import check_boundaries, check_positive, phi_estimate
from .checkpoint import Checkpoint, digest
from .result import GenerationResult
from .soft_quench import (BOUNDARY_KINDS, PHI_START_FACTOR, SETTLE_EXCESS, TARGET_AIM,
                          SettleAsker, _check_box, _Run, _shrunk_result, _SoftSpheres,
                          check_quench_options, pressure_ladder, quench_and_shrink)

__all__ = ["relax", "RELAX_START_PRESSURE", "RELAX_PRESSURE_REDUCTION", "SETTLE_EXCESS"]

#: Pressure of the first minimisation of `relax` (ε / (mean diameter)^d): the input is
#: inflated to it. Lower than the quench's 1e-2 from random centres, since the input is
#: already near a jamming point and every rung above it would move it further.
RELAX_START_PRESSURE = 1e-4
#: Smallest factor between the pressures of two successive minimisations of `relax` when
#: the caller gives none: the quench's (`soft_quench.PRESSURE_REDUCTION`); the ladder's
#: cost against its factor: docs/notes/relaxed-route.md.
RELAX_PRESSURE_REDUCTION = 0.1


def relax(packing: Packing, *, start_pressure: float = RELAX_START_PRESSURE,
          target_pressure: float | None = None, force_tolerance: float = 1e-6,
          progress: bool = False, skin: float = 0.2, max_steps: int = 50_000_000,
          checkpoint: str | os.PathLike | None = None, checkpoint_every: float = 60.0,
          minimiser: str = "auto", max_displacement: float | None = None,
          pressure_reduction: float = RELAX_PRESSURE_REDUCTION,
          settle: Callable[[GenerationResult], str | None] | None = None,
          settle_excess: int = SETTLE_EXCESS) -> GenerationResult:
    """Relax a configuration as harmonic soft spheres to a vanishing pressure, then shrink
    it to hard contact, in its own box.

    The particles keep their positions as the start and their diameters' ratios; the box
    and the boundaries do not change. The diameters are inflated (one common factor, a
    degree of freedom of the enthalpy H = E + p* V) to the pressure `start_pressure` and
    the enthalpy is minimised; the pressure then goes down in equal factors of at least
    `pressure_reduction` to half of `target_pressure`, and the last minimum is tightened and
    shrunk to hard contact exactly as in `soft_quench` (same minimisers, same convergence
    tests, same shrink). The common translation of the particles along the periodic axes
    is taken out at the end. Given `max_displacement`, the relaxation stops as soon as a
    particle lies further than that from its place in the input (checked every 1000
    minimiser steps and at every list rebuild), and returns the state it reached, shrunk to
    hard contact. Given `settle`, the relaxation asks it after every rung but the last, and
    within a rung where the overlap network stops changing, whether the state reached will
    do, and ends there when it will.

    Parameters
    ----------
    packing : calippso.Packing
        The configuration: positions, diameters, box and boundaries (periodic, flat walls or
        a cylinder). It may overlap (soft spheres): the first minimisation removes the
        overlaps above the start pressure.
    start_pressure : float
        Pressure of the first minimisation, ε / (mean diameter)^d (default 1e-4).
    target_pressure : float, optional
        The last minimum has half this pressure. Default: `default_target_pressure` (as
        `soft_quench`).
    force_tolerance, progress, skin, max_steps, checkpoint_every, minimiser
        As in `soft_quench`.
    checkpoint : str or PathLike, optional
        File (``.npz``) of the run's state, written and resumed as in `soft_quench`; it
        belongs to this input and these options (`max_steps` and `max_displacement` aside:
        a run they stopped continues from it with larger ones).
    max_displacement : float, optional
        Stop once a particle lies further than this from the input (mean diameters of the
        input; minimum image, common translation along the periodic axes taken out). The
        status then names the particle and its distance. None: no bound.
    pressure_reduction : float
        Smallest factor between two successive pressures of the ladder, in (0, 1) (default
        0.1, as `soft_quench`: from 1e-4 to half the default target of 1e-6 in three steps).
    settle, settle_excess
        As in `soft_quench`: ``settle(reached)`` decides whether the relaxation ends at a
        settled state (`reached` as this function returns it, from the input's box).

    Returns
    -------
    GenerationResult
        As `soft_quench`'s, except that `packing` has the input's box and boundaries, the
        particles in the input order, and the input's diameters times one factor (``extra
        ["diameter_factor"]``). `contacts` is the overlap network before the shrink
        (rattlers removed): ``calippso.jam(result.packing, network=result.contacts)``
        certifies it. `extra` adds ``start_pressure``, ``phi_input`` (φ of the input),
        ``max_displacement`` and ``median_displacement`` (of the particles from the input,
        minimum image, common translation taken out, in mean diameters of the input),
        ``farthest`` (the particle that moved furthest) and
        ``translation`` (the common translation taken out, shape (d,), length units);
        ``rungs`` (pressures of the ladder), ``rung`` (the rungs in `history`) and ``halted``
        (True when `max_displacement` stopped the run: `history` then holds the rungs it
        began, the last one unfinished); ``settled`` (the reason `settle` gave, or None).

    Raises
    ------
    ValueError
        On a packing that is not a `calippso.Packing`, non-positive pressures, tolerance,
        skin or `max_displacement`, a `pressure_reduction` outside (0, 1), a start pressure
        below the target, a non-positive max_steps, too few particles for the box, or a
        checkpoint file that belongs to another run.
    """
    wall = time.perf_counter()
    if not isinstance(packing, Packing):
        raise ValueError(f"relax takes a calippso.Packing, got {type(packing).__name__}")
    n, d = packing.n, packing.d
    boundaries = check_boundaries(packing.boundaries, d, "relax", BOUNDARY_KINDS)
    target_pressure, force_tolerance, skin, minimiser = check_quench_options(
        n, d, boundaries, target_pressure, force_tolerance, skin, max_steps, minimiser)
    start_pressure = check_positive(start_pressure, "start_pressure")
    if max_displacement is not None:
        max_displacement = check_positive(max_displacement, "max_displacement")
    if not 0.0 < pressure_reduction < 1.0:
        raise ValueError(f"pressure_reduction must lie in (0, 1), got {pressure_reduction!r}")
    if start_pressure < target_pressure:
        raise ValueError(f"start_pressure {start_pressure:g} is below target_pressure "
                         f"{target_pressure:g}")
    signature = {"input": digest(packing.positions, packing.diameters, packing.box),
                 "boundaries": str(boundaries), "start_pressure": start_pressure,
                 "target_pressure": target_pressure, "force_tolerance": force_tolerance,
                 "skin": skin, "minimiser": minimiser,
                 "pressure_reduction": pressure_reduction}
    saver = Checkpoint(checkpoint, "relax", signature,
                       every=check_positive(checkpoint_every, "checkpoint_every",
                                            allow_zero=True))
    mean = packing.mean_diameter
    box = packing.box / mean
    nominal = packing.diameters / mean
    start = wrap(packing.positions, packing.box, boundaries.periodic) / mean
    _check_box(box, nominal, skin, packing.phi,
               max(packing.phi, PHI_START_FACTOR * phi_estimate(d)), boundaries.periodic)
    system = _SoftSpheres(start, nominal, box, skin, minimiser, boundaries.periodic,
                          boundaries.cylinder_axes)
    run = _Run(pressure_ladder(start_pressure, TARGET_AIM * target_pressure,
                               pressure_reduction), force_tolerance, max_steps)
    bound = None if max_displacement is None else _Bound(start, box, boundaries.periodic,
                                                         max_displacement)
    def reached(system: _SoftSpheres, rung: int, pressure: float) -> GenerationResult:
        shrunk = _shrunk_result(system, packing.diameters, mean, boundaries, run.rows,
                                pressure, target_pressure, f"relaxed at pressure "
                                f"{pressure:.3g}, rung {rung} of {len(run.ladder)}", wall,
                                False, packing.box)
        shrunk.extra.update(rungs=run.ladder.copy(), halted=False)
        return _aligned(shrunk, packing, start_pressure)

    asker = None if settle is None else SettleAsker(settle, settle_excess, run, reached)

    def watch(reached: _SoftSpheres) -> str | None:
        if bound is not None and bound(reached) is not None:
            return bound.reason
        return None if asker is None else asker.at_pause(reached)

    result = quench_and_shrink(system, run, saver, packing.diameters, boundaries,
                               target_pressure, progress, wall, box=packing.box,
                               watch=None if bound is None and asker is None else watch,
                               settled=None if asker is None else asker.after_rung)
    result.extra.update(rungs=run.ladder.copy(), rung=len(run.rows),
                        halted=bound is not None and bound.reason is not None,
                        settled=run.settled_by or (None if asker is None else asker.reason))
    return _aligned(result, packing, start_pressure)


class _Bound:
    """The watch of a bounded relaxation (`quench_and_shrink`): the reason to stop once a
    particle lies further than `limit` from `start`.

    Parameters
    ----------
    start : ndarray, shape (N, d)
        The input's positions (mean diameters).
    box : ndarray, shape (d,)
        Box sides (mean diameters).
    periodic : ndarray, shape (d,), bool
    limit : float
        Largest distance from `start` (mean diameters).
    """

    def __init__(self, start: np.ndarray, box: np.ndarray, periodic: np.ndarray,
                 limit: float) -> None:
        self.start, self.box, self.periodic, self.limit = start, box, periodic, limit
        self.reason: str | None = None

    def __call__(self, system: _SoftSpheres) -> str | None:
        lengths, _ = displacements(self.start, system.positions(), self.box, self.periodic)
        farthest = int(np.argmax(lengths))
        if lengths[farthest] > self.limit:
            self.reason = (f"particle {farthest} lies {lengths[farthest]:.3g} mean diameters "
                           f"from the input, more than max_displacement = {self.limit:g}")
        return self.reason


def _aligned(result: GenerationResult, packing: Packing,
             start_pressure: float) -> GenerationResult:
    """`result` with the common translation from `packing` taken out, and the distance
    from it recorded in ``extra``."""
    relaxed = result.packing
    lengths, translation = displacements(packing.positions, relaxed.positions, packing.box,
                                         packing.periodic)
    result.packing = Packing(relaxed.positions - translation, relaxed.diameters, relaxed.box,
                             relaxed.boundaries).wrapped()
    mean = packing.mean_diameter
    result.extra.update(start_pressure=start_pressure, phi_input=packing.phi,
                        diameter_factor=float(relaxed.diameters.mean()) / mean,
                        max_displacement=float(lengths.max()) / mean,
                        farthest=int(np.argmax(lengths)),
                        median_displacement=float(np.median(lengths)) / mean,
                        translation=translation)
    return result
