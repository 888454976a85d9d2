"""Compile the generators' Numba kernels ahead of their first real use.

The kernels are compiled on first call and cached on disk (``cache=True``), next to the
package or under ``NUMBA_CACHE_DIR``. A fresh install therefore pays the compilation, about
a minute and a half on one core, in the first generator call of every kernel. `precompile`
pays it up front, spread over several processes, by running each generator once on a tiny
system in every container: a fresh machine, a container image or a batch job can then start
from warm caches. From the shell::

    python -m generators.precompile            # one process per core
    python -m generators.precompile --jobs 1
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import numpy as np

#: Particles in each warm-up system: enough for every neighbour-list path, quick to run.
WARMUP_PARTICLES = 64
#: Size ratio of the warm-up's bidisperse spheres.
WARMUP_SIZE_RATIO = 1.4
#: Pressure at which the warm-up runs of the event-driven generators stop.
WARMUP_PRESSURE = 1e2
#: Pressure at which the warm-up soft quenches stop.
WARMUP_QUENCH_PRESSURE = 1e-4
#: Steps of the warm-up runs of the force-biased generators.
WARMUP_FB_STEPS = 200
#: Rods in the spherocylinder warm-up (its box takes no fewer at the default start).
WARMUP_RODS = 128
#: Aspect ratio of the warm-up spherocylinders.
WARMUP_ROD_ASPECT_RATIO = 2.0
#: Dimensions of the warm-up systems: d = 3 has kernels of its own, d = 2 the generic ones.
WARMUP_DIMENSIONS = (2, 3)


def _containers():
    """(d, boundaries) of every warm-up system: `WARMUP_DIMENSIONS` × periodic, flat walls,
    a cylinder (d ≥ 3)."""
    from calippso.geometry.boundaries import Boundaries

    for d in WARMUP_DIMENSIONS:
        yield d, None
        yield d, Boundaries.walls(d, (0,))
        if d >= 3:
            yield d, Boundaries.cylinder(d, (0, 1))


def _diameters() -> np.ndarray:
    """`WARMUP_PARTICLES` bidisperse diameters (1 and `WARMUP_SIZE_RATIO`)."""
    return np.where(np.arange(WARMUP_PARTICLES) % 2 == 0, 1.0, WARMUP_SIZE_RATIO)


def _collision_and_push_driven() -> None:
    """LS (from diameters and from a packing), MLS and FB in every container, and the
    spherocylinders' FB."""
    from . import closest_jamming, force_biased, lubachevsky_stillinger
    from .spherocylinders import force_biased as rods_force_biased

    for d, boundaries in _containers():
        grown = lubachevsky_stillinger(_diameters(), d, target_pressure=WARMUP_PRESSURE,
                                       boundaries=boundaries)
        lubachevsky_stillinger(start=grown.packing, target_pressure=2 * WARMUP_PRESSURE)
        if boundaries is None:
            closest_jamming(_diameters(), d, max_pressure=WARMUP_PRESSURE)
        force_biased(_diameters(), d, boundaries=boundaries, max_steps=WARMUP_FB_STEPS)
    rods_force_biased(WARMUP_RODS, WARMUP_ROD_ASPECT_RATIO, max_steps=WARMUP_FB_STEPS)


def _energy_minimising() -> None:
    """The soft quench with each minimiser, and the relaxation of its result, in every
    container."""
    from . import relax, soft_quench

    for d, boundaries in _containers():
        for minimiser in ("fire", "lbfgs", "newton"):
            quenched = soft_quench(_diameters(), d, target_pressure=WARMUP_QUENCH_PRESSURE,
                                   minimiser=minimiser, boundaries=boundaries)
        relax(quenched.packing, target_pressure=WARMUP_QUENCH_PRESSURE)


def warmup_tasks() -> list[Callable[[], None]]:
    """The warm-up runs. Each compiles its own family of kernels, so that processes running
    them side by side do not compile the same kernel twice."""
    return [_energy_minimising, _collision_and_push_driven]


def _run(task: Callable[[], None]) -> None:
    task()


def precompile(jobs: int | None = None) -> float:
    """Compile and cache every generator kernel; return the wall time it took, in s.

    Parameters
    ----------
    jobs : int, optional
        Processes that compile side by side (default: one per core). With 1, the
        compilation runs in this process.
    """
    jobs = min(jobs or os.cpu_count() or 1, len(warmup_tasks()))
    start = time.perf_counter()
    tasks = warmup_tasks()
    if jobs == 1:
        for task in tasks:
            _run(task)
    else:
        with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as pool:
            list(pool.map(_run, tasks))
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=None,
                        help="processes compiling side by side (default: one per core)")
    arguments = parser.parse_args(argv)
    seconds = precompile(arguments.jobs)
    print(f"generator kernels compiled and cached in {seconds:.1f} s")


if __name__ == "__main__":
    main()
