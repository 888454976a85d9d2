"""Small test configurations, built without the generators (so core tests stay independent),
except `ls_packing` and `mls_start`, which import them when called."""

from __future__ import annotations

import numpy as np

from calippso import Packing
from calippso.geometry.boundaries import Boundaries
from calippso.geometry.packing import ball_volume


def random_sequential_addition(n: int, d: int, phi: float, seed: int = 0,
                               diameters: np.ndarray | None = None,
                               boundaries: Boundaries | None = None) -> Packing:
    """Non-overlapping random configuration: insert spheres one by one at random free places.

    Parameters
    ----------
    n, d : int
        Particles and dimension.
    phi : float
        Target packing fraction (must be below the random-sequential-addition limit).
    diameters : ndarray, optional
        Diameters (mean scaled to 1); monodisperse by default. Inserted largest first.
    boundaries : Boundaries, optional
        Flat walls (`Boundaries.walls`) or a cylinder (`Boundaries.cylinder`); a sphere is
        then placed inside the container, of volume fraction `phi`. Periodic by default.
    """
    rng = np.random.default_rng(seed)
    sizes = np.ones(n) if diameters is None else np.asarray(diameters, float) / np.mean(diameters)
    shape = 1.0 if boundaries is None else boundaries.volume(np.ones(d))
    side = (np.sum(ball_volume(d, sizes / 2)) / (phi * shape)) ** (1.0 / d)
    box = np.full(d, side)
    periodic = np.ones(d, bool) if boundaries is None else boundaries.periodic
    walls = () if boundaries is None else boundaries.wall_axes
    plane = [] if boundaries is None else list(boundaries.cylinder_axes)
    order = np.argsort(-sizes)
    placed = np.zeros((0, d))
    placed_sizes = np.zeros(0)
    for k in order:
        for _ in range(100000):
            trial = rng.random(d) * side
            for axis in walls:
                trial[axis] = 0.5 * sizes[k] + rng.random() * (side - sizes[k])
            if plane and np.linalg.norm(trial[plane] - 0.5 * side) > 0.5 * (side - sizes[k]):
                continue
            delta = placed - trial
            delta -= np.where(periodic, box, 0.0) * np.round(delta / box)
            if np.all(np.einsum("nd,nd->n", delta, delta) > (0.5 * (placed_sizes + sizes[k])) ** 2):
                placed = np.vstack([placed, trial])
                placed_sizes = np.append(placed_sizes, sizes[k])
                break
        else:
            raise RuntimeError(f"could not place particle {len(placed)} at phi = {phi}")
    return Packing(placed, placed_sizes, box, boundaries)


def bidisperse(n: int, ratio: float = 1.4) -> np.ndarray:
    """50:50 mixture of diameters 1 and `ratio`."""
    sizes = np.ones(n)
    sizes[n // 2:] = ratio
    return sizes


def lognormal(n: int, std: float, seed: int = 0) -> np.ndarray:
    """Log-normal diameters with mean 1 and standard deviation `std`."""
    rng = np.random.default_rng(seed)
    s2 = np.log(1.0 + std**2)
    return rng.lognormal(-0.5 * s2, np.sqrt(s2), n)


def overlap_free(packing: Packing) -> float:
    """Smallest relative gap over all pairs in contact range, by brute force (independent check)."""
    delta = packing.positions[:, None, :] - packing.positions[None, :, :]
    delta -= packing.box * np.round(delta / packing.box)
    distance = np.sqrt(np.einsum("ijd,ijd->ij", delta, delta))
    sigma = 0.5 * (packing.diameters[:, None] + packing.diameters[None, :])
    gaps = distance / sigma - 1.0
    np.fill_diagonal(gaps, np.inf)
    return float(gaps.min())


def ls_packing(n: int, d: int, seed: int, pressure: float = 1e12) -> Packing:
    """Monodisperse Lubachevsky–Stillinger state at reduced pressure `pressure` (gaps ~ σ/p)."""
    import generators

    return generators.lubachevsky_stillinger(generators.diameters.monodisperse(n), d=d,
                                             target_pressure=pressure, seed=seed).packing


def phi_j(d: int) -> float:
    """Typical jamming density of monodisperse spheres (d = 3, 4, 5)."""
    return {3: 0.64, 4: 0.46, 5: 0.31}[d]


#: Arguments of the MLS run shared by the generator tests (`mls_jammed` in conftest.py).
MLS_ARGS = dict(max_pressure=1e9, final_rate=1e-3, seed=6)


def mls_start() -> Packing:
    """The start of that MLS run: 64 Poisson points in d = 3 at φ = 0.3."""
    import generators

    return generators.poisson(generators.diameters.monodisperse(64), 3, phi=0.3, seed=6)


def container_gaps(packing: Packing) -> tuple[np.ndarray, np.ndarray]:
    """Relative gaps of every pair (minimum image along the periodic axes, in a sheared box
    too), and of every particle to every flat wall and to the cylinder."""
    delta = packing.minimum_image(packing.positions[:, None, :] - packing.positions[None, :, :])
    sigma = 0.5 * (packing.diameters[:, None] + packing.diameters[None, :])
    pairs = np.linalg.norm(delta, axis=2) / sigma - 1
    radius = packing.diameters / 2
    walls = [np.minimum(packing.positions[:, axis], packing.box[axis]
                        - packing.positions[:, axis]) / radius - 1
             for axis in packing.boundaries.wall_axes]
    if packing.boundaries.cylinder_axes:
        axes = list(packing.boundaries.cylinder_axes)
        rho = np.linalg.norm(packing.positions[:, axes] - 0.5 * packing.box[axes], axis=1)
        walls.append((0.5 * packing.box[axes[0]] - rho) / radius - 1)
    return pairs[np.triu_indices(packing.n, 1)], np.concatenate([np.zeros(0), *walls])
