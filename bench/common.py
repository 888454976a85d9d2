"""Inputs shared by the benchmarks that the library does not make.

Imported as a sibling module (``from common import …``): the scripts run as
``python bench/NAME.py`` from the repository root, which puts ``bench/`` on the import path.
"""

from __future__ import annotations

import numpy as np

from calippso import Packing
from calippso.packing import ball_volume

__all__ = ["random_sequential_addition"]

#: Random trial centres drawn for one sphere before the density is declared too high.
MAX_TRIALS = 100_000


def random_sequential_addition(n: int, d: int, phi: float, seed: int = 0) -> Packing:
    """Monodisperse spheres inserted one by one at random free places of a periodic box.

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

    Returns
    -------
    Packing
        n spheres of diameter 1 in a cubic box of side (n V_d(1/2) / phi)^(1/d) (length
        units of the diameter), no two overlapping.

    Raises
    ------
    RuntimeError
        A sphere found no free place in `MAX_TRIALS` trials.
    """
    rng = np.random.default_rng(seed)
    side = (float(np.sum(ball_volume(d, np.full(n, 0.5)))) / phi) ** (1.0 / d)
    box = np.full(d, side)
    placed = np.zeros((0, d))
    for _ in range(n):
        for _ in range(MAX_TRIALS):
            trial = rng.random(d) * side
            delta = placed - trial
            delta -= box * np.round(delta / box)
            if np.all(np.einsum("nd,nd->n", delta, delta) > 1.0):
                placed = np.vstack([placed, trial])
                break
        else:
            raise RuntimeError(f"could not place particle {len(placed)} at phi = {phi}")
    return Packing(placed, np.ones(n), box)
