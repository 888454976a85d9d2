"""Inputs shared by the benchmarks that the library does not make.

Imported as a sibling module (``from common import …``): the scripts run as
``python bench/NAME.py`` from the repository root, which puts ``bench/`` on the import path.
"""

from __future__ import annotations

import numpy as np

from calippso import Boundaries, Packing
from calippso.geometry.packing import ball_volume

__all__ = ["random_sequential_addition"]

#: Random trial centres drawn for one sphere before the density is declared too high.
MAX_TRIALS = 100_000


def random_sequential_addition(n: int, d: int, phi: float, seed: int = 0,
                               boundaries: Boundaries | None = None,
                               sides: np.ndarray | None = None,
                               diameters: np.ndarray | None = None) -> Packing:
    """Spheres inserted one by one at random free places of a box (periodic, or with flat
    walls).

    The builder of the test configurations (``tests/configurations.py``): with the same seed
    it draws the same trial centres, so a benchmark input is the packing the tests use.

    Parameters
    ----------
    n : int
        Number of spheres.
    d : int
        Dimension.
    phi : float
        Packing fraction, which sets the box side; it must be below the random sequential
        addition limit (about 0.38 in d = 3).
    seed : int
        Seed of the trial centres.
    boundaries : Boundaries, optional
        Flat walls (`Boundaries.walls`): along their axes a centre lies in [1/2, L − 1/2]; or
        a cylinder (`Boundaries.cylinder`): a centre lies inside its circle, and `phi` is the
        fraction of the cylinder's volume. Periodic by default.
    sides : ndarray, shape (d,), optional
        Box sides in proportion (scaled to reach `phi`); a cube by default.
    diameters : ndarray, shape (n,), optional
        Diameters (scaled to mean 1), inserted largest first; all 1 by default.

    Returns
    -------
    Packing
        n spheres of mean diameter 1 in a box of volume Σ V_d(σ_i/2) / phi (length units of
        the mean diameter), no two overlapping.

    Raises
    ------
    RuntimeError
        A sphere found no free place in `MAX_TRIALS` trials.
    """
    rng = np.random.default_rng(seed)
    shape = np.ones(d) if sides is None else np.asarray(sides, float) / np.prod(sides) ** (1 / d)
    sizes = np.ones(n) if diameters is None else np.asarray(diameters, float) / np.mean(diameters)
    container = 1.0 if boundaries is None else boundaries.volume(shape)
    box = shape * (float(np.sum(ball_volume(d, sizes / 2))) / (phi * container)) ** (1.0 / d)
    periodic = np.ones(d, bool) if boundaries is None else boundaries.periodic
    plane = [] if boundaries is None else list(boundaries.cylinder_axes)
    placed = np.zeros((0, d))
    placed_sizes = np.zeros(0)
    for k in np.argsort(-sizes, kind="stable"):
        for _ in range(MAX_TRIALS):
            draw = rng.random(d)
            trial = np.where(periodic, draw * box, 0.5 * sizes[k] + draw * (box - sizes[k]))
            if plane and np.linalg.norm(trial[plane] - 0.5 * box[plane]) > 0.5 * (
                    box[plane[0]] - sizes[k]):
                continue
            delta = placed - trial
            delta -= np.where(periodic, box, 0.0) * np.round(delta / box)
            if np.all(np.einsum("nd,nd->n", delta, delta) > (0.5 * (placed_sizes + sizes[k]))**2):
                placed = np.vstack([placed, trial])
                placed_sizes = np.append(placed_sizes, sizes[k])
                break
        else:
            raise RuntimeError(f"could not place particle {len(placed)} at phi = {phi}")
    return Packing(placed, placed_sizes, box, boundaries)
