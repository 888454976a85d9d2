"""Protocols: how a start is made before `calippso.jam` runs, above both the loop and the
generators.

* `make_diameters`: diameters of a named distribution;
* `EnsembleSpec` and `make_start`: a start of a named kind (LS, FB, MLS or random centres),
  as an ensemble makes one per seed;
* `precompress`: Lubachevsky–Stillinger compression of a loose start, run before `jam`.

The jamming loop never imports this module. It imports the `generators` package (and with it
numba) only inside the functions that run a generator.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .geometry.packing import Packing

if TYPE_CHECKING:
    from generators import GenerationResult

__all__ = ["DISTRIBUTIONS", "PROTOCOLS", "EnsembleSpec", "OVERLAP_TOLERANCE", "PRECOMPRESS_SEED",
           "make_diameters", "make_start", "precompress", "precompress_checkpoint",
           "precompress_note"]

#: Kinds of start `make_start` makes (see `EnsembleSpec.protocol`).
PROTOCOLS = ("ls", "fb", "mls", "poisson")
#: Diameter distributions `make_diameters` knows.
DISTRIBUTIONS = ("monodisperse", "bidisperse", "lognormal")
#: Seed of the LS velocities in `precompress`: the stage is deterministic, so a resumed run
#: repeats it exactly.
PRECOMPRESS_SEED = 0
#: Overlaps a start given to `precompress` may have, as a relative gap h = |r|/σ − 1 > −this:
#: round-off, as `calippso.JamSettings.overlap_tolerance` accepts by default.
OVERLAP_TOLERANCE = 1e-10


def make_diameters(n: int, distribution: str, *, ratio: float = 1.4, std: float = 0.1,
                   seed: int = 0) -> np.ndarray:
    """Diameters from `generators.diameters` by distribution name.

    Parameters
    ----------
    n : int
        Number of particles.
    distribution : {"monodisperse", "bidisperse", "lognormal"}
        Equal diameters; a 50:50 mixture of 1 and `ratio`; log-normal with mean 1 and
        standard deviation `std`.
    ratio, std : float
        Parameters of the bidisperse and log-normal distributions.
    seed : int
        Seed of the bidisperse order and of the log-normal sample.

    Returns
    -------
    ndarray, shape (n,)
        Diameters (length units: the mean, or the small, diameter is 1).
    """
    from generators import diameters

    if distribution == "bidisperse":
        return diameters.bidisperse(n, ratio=ratio, seed=seed)
    if distribution == "lognormal":
        return diameters.lognormal(n, std=std, seed=seed)
    if distribution == "monodisperse":
        return diameters.monodisperse(n)
    raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {distribution!r}")


@dataclass(frozen=True)
class EnsembleSpec:
    """What every packing of an ensemble is (only the seed differs).

    Attributes
    ----------
    protocol : {"ls", "fb", "mls", "poisson"}
        How the start is made: Lubachevsky–Stillinger to `pressure`, force-biased, closest
        jamming (MLS) from random centres, or random centres at packing fraction `phi`
        scaled to no overlap (jamming from a low-density start).
    n, d : int
        Particles and dimension.
    distribution : {"monodisperse", "bidisperse", "lognormal"}
        Diameters: equal; 50:50 with size ratio `ratio`; log-normal with std `std`.
    ratio, std : float
        Parameters of the distribution.
    pressure : float
        LS target reduced pressure.
    final_growth_rate : float, optional
        LS only: a slow end, this growth rate from reduced pressure 1e3 on (e.g. 1e-4 with
        `pressure` 1e7); the start is then a jamming point up to d/p
        (docs/howto/start-configurations.md).
    phi : float
        Packing fraction of the random centres of the "poisson" and "mls" starts (after
        removing overlaps the "poisson" start is looser).
    precompress : float, optional
        Compress every start by LS to this reduced pressure before jamming it (`precompress`);
        for loose starts ("fb", "poisson").
    solver : str
        LP backend of `calippso.jam`.
    jam_options : dict
        Further keyword arguments of `calippso.jam`.
    """

    protocol: str = "ls"
    n: int = 128
    d: int = 3
    distribution: str = "monodisperse"
    ratio: float = 1.4
    std: float = 0.1
    pressure: float = 1e5
    final_growth_rate: float | None = None
    phi: float = 0.3
    precompress: float | None = None
    solver: str = "highs"
    jam_options: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.protocol not in PROTOCOLS:
            raise ValueError(f"protocol must be one of {PROTOCOLS}, got {self.protocol!r}")
        if self.distribution not in DISTRIBUTIONS:
            raise ValueError(
                f"distribution must be one of {DISTRIBUTIONS}, got {self.distribution!r}"
            )
        if int(self.n) < 2 or int(self.d) < 2:
            raise ValueError(f"need n >= 2 and d >= 2, got n = {self.n}, d = {self.d}")
        for name in ("ratio", "std", "pressure", "phi"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("final_growth_rate", "precompress"):
            value = getattr(self, name)
            if value is not None and not value > 0:
                raise ValueError(f"{name} must be > 0 or None, got {value}")

    @classmethod
    def of(cls, spec: "EnsembleSpec | dict") -> "EnsembleSpec":
        """An `EnsembleSpec` from itself or from a dict of its fields."""
        if isinstance(spec, cls):
            return spec
        unknown = set(spec) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown ensemble spec keys {sorted(unknown)}")
        return cls(**spec)


def make_start(spec: EnsembleSpec, seed: int, *,
               checkpoint: str | os.PathLike | None = None) -> "GenerationResult":
    """Make the start of one packing of kind `spec.protocol`, with diameters and generator
    seeded by `seed`.

    Parameters
    ----------
    spec : EnsembleSpec
        The kind of start, its size and its parameters.
    seed : int
        Seed of the diameters and of the generator.
    checkpoint : str or PathLike, optional
        State file of the LS and MLS generators (resumed if it exists).

    Returns
    -------
    generators.GenerationResult
        The start and how its run went. The "poisson" start has no run: reduced pressure
        nan, 0 steps.
    """
    import generators

    from .geometry.neighbors import contact_shrink

    sizes = make_diameters(spec.n, spec.distribution, ratio=spec.ratio, std=spec.std, seed=seed)
    if spec.protocol == "ls":
        return generators.lubachevsky_stillinger(
            sizes, spec.d, seed=seed, target_pressure=spec.pressure, checkpoint=checkpoint,
            final_growth_rate=spec.final_growth_rate,
        )
    if spec.protocol == "fb":
        return generators.force_biased(sizes, spec.d, seed=seed)
    if spec.protocol == "mls":
        return generators.closest_jamming(sizes, spec.d, seed=seed, phi_start=spec.phi,
                                          checkpoint=checkpoint)
    began = time.perf_counter()
    packing = generators.poisson(sizes, spec.d, phi=spec.phi, seed=seed)
    shrink = contact_shrink(packing.positions, packing.diameters, packing.box)
    packing = packing.scaled_to_phi(packing.phi * shrink**spec.d)
    return generators.GenerationResult(
        packing=packing, reduced_pressure=float("nan"), steps=0,
        wall_time=time.perf_counter() - began,
        status=f"random centres at phi = {spec.phi:g}, diameters shrunk to no overlap")


def precompress_checkpoint(checkpoint: str | os.PathLike | None) -> Path | None:
    """The LS stage's own checkpoint file beside the loop's: ``run.npz`` → ``run.precompress.npz``."""
    if checkpoint is None:
        return None
    path = Path(checkpoint)
    return path.with_name(f"{path.stem}.precompress.npz")


def precompress(packing: Packing, pressure: float, *,
                checkpoint: str | os.PathLike | None = None) -> "GenerationResult":
    """Compress a loose start by Lubachevsky–Stillinger (LS) event-driven MD to `pressure`.

    From a loose start (a force-biased packing at φ ≈ 0.60, a random one at φ ≈ 0.2) the LP
    loop of `calippso.jam` crawls: every LP ends at a configuration jammed to first order,
    and the next one gains only what the neglected |s|² term opened, so hundreds of LPs are
    needed. LS compression takes such a start close to jamming, keeping the particles, their
    order, the box and the diameter ratios; `jam` of the compressed packing then needs few
    LPs. The jammed packing is the CALiPPSO fixed point reached from the compressed state,
    not from the start itself. The run is deterministic (velocities seeded by
    `PRECOMPRESS_SEED`).

    Parameters
    ----------
    packing : Packing
        Overlap-free start (overlaps within `OVERLAP_TOLERANCE` are round-off and removed
        by a uniform shrink).
    pressure : float
        Target reduced pressure βP/ρ (> 0); 1e5 leaves gaps ~1e-5 of a diameter.
    checkpoint : str or PathLike, optional
        The LS run's checkpoint file, resumed if it exists (`generators.checkpoint`). Beside a
        `jam` checkpoint ``run.npz`` it is ``run.precompress.npz`` (`precompress_checkpoint`).

    Returns
    -------
    generators.GenerationResult
        The LS run: `packing` holds the same particles in the same order and the same box,
        diameters grown by one common factor. `precompress_note` describes it in one line.

    Raises
    ------
    ValueError
        On a pressure that is not a positive number, duplicated particles, or particles that
        overlap beyond round-off (the message names the worst pair).
    """
    if not (isinstance(pressure, (int, float, np.floating)) and np.isfinite(pressure)
            and pressure > 0):
        raise ValueError(f"pressure must be a finite number > 0, got {pressure!r}")
    _check_no_overlap(packing)
    import generators

    return generators.lubachevsky_stillinger(start=packing, seed=PRECOMPRESS_SEED,
                                             target_pressure=float(pressure),
                                             checkpoint=checkpoint)


def precompress_note(start: Packing, run: "GenerationResult") -> str:
    """One line on a `precompress` run: φ before and after, pressure, collisions, wall time."""
    return (f"input compressed by Lubachevsky-Stillinger MD before the LP loop: phi "
            f"{start.phi:.6f} -> {run.packing.phi:.6f}, reduced pressure "
            f"{run.reduced_pressure:.2e}, {run.steps / start.n:.0f} collisions per "
            f"particle, {run.wall_time:.1f} s")


def _check_no_overlap(packing: Packing) -> None:
    """ValueError naming duplicated particles, or the worst pair if two particles overlap
    beyond `OVERLAP_TOLERANCE` (`calippso.inputs.check_input_overlaps`, as `jam` checks)."""
    from .inputs import check_input_overlaps
    from .geometry.neighbors import NeighborSearch

    scale = packing.mean_diameter
    check_input_overlaps(NeighborSearch(packing.positions / scale, packing.diameters / scale,
                                        packing.box / scale, packing.periodic),
                         OVERLAP_TOLERANCE)
