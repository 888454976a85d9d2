"""Random (Poisson) starting configurations."""

from __future__ import annotations

import numpy as np

from calippso.packing import Packing, ball_volume

from ._checks import check_diameters, check_dimension, check_phi

__all__ = ["poisson"]


def poisson(diameters, d: int, phi: float, seed: int = 0) -> Packing:
    """Uniform random centres in a cubic periodic box; the spheres overlap freely.

    Parameters
    ----------
    diameters : array_like, shape (N,)
        Diameters σ_i > 0 (length units).
    d : int
        Dimension (≥ 2).
    phi : float
        Packing fraction Σ V_d(σ_i/2) / L^d in (0, 1), which sets the box side L.
    seed : int
        Seed of the centres.

    Returns
    -------
    Packing
        Positions in [0, L)^d.
    """
    diameters = check_diameters(diameters)
    d = check_dimension(d)
    phi = check_phi(phi)
    side = (float(np.sum(ball_volume(d, diameters / 2))) / phi) ** (1.0 / d)
    if diameters.max() >= 0.5 * side:
        raise ValueError(
            f"too few particles for phi = {phi}: the box side {side:.3g} is not above twice the "
            f"largest diameter {diameters.max():.3g}; use more particles or a lower phi"
        )
    positions = np.random.default_rng(seed).uniform(0.0, side, size=(diameters.shape[0], d))
    return Packing(positions, diameters, np.full(d, side)).wrapped()
