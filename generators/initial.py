"""Where a generator starts: random (Poisson) centres, or a packing the caller gives."""

from __future__ import annotations

import warnings

import numpy as np

from calippso.geometry.boundaries import PERIODIC, Boundaries
from calippso.geometry.packing import Packing, ball_volume

from ._checks import check_boundaries, check_diameters, check_dimension, check_phi

__all__ = ["poisson", "start_of"]


def poisson(diameters, d: int, *, phi: float, seed: int = 0,
            boundaries: Boundaries | None = None) -> Packing:
    """Uniform random centres in a cubic box, inside its container; the spheres overlap
    freely with each other, never with a wall.

    Parameters
    ----------
    diameters : array_like, shape (N,)
        Diameters σ_i > 0 (length units).
    d : int
        Dimension (≥ 2).
    phi : float
        Packing fraction Σ V_d(σ_i/2) / V in (0, 1), with V the container's volume (L^d, or
        the cylinder inscribed in the cube), which sets the box side L.
    seed : int
        Seed of the centres.
    boundaries : Boundaries, optional
        The container (`calippso.geometry.boundaries`); default periodic along every axis. Along an
        axis with walls a centre lies in [σ_i/2, L − σ_i/2]; in a cylinder's circle, within
        (L − σ_i)/2 of its axis (uniform over that disc).

    Returns
    -------
    Packing
        Positions in [0, L)^d, with these boundaries. A start, not a run: the one maker that
        returns a `Packing` rather than a `GenerationResult`.
    """
    diameters = check_diameters(diameters)
    d = check_dimension(d)
    phi = check_phi(phi)
    boundaries = Boundaries.all_periodic(d) if boundaries is None else boundaries
    if boundaries.d != d:
        raise ValueError(f"boundaries have {boundaries.d} axes, expected d = {d}")
    volume = float(np.sum(ball_volume(d, diameters / 2))) / phi
    side = (volume / boundaries.volume(np.ones(d))) ** (1.0 / d)
    if boundaries.n_periodic and diameters.max() >= 0.5 * side:
        raise ValueError(
            f"too few particles for phi = {phi}: the box side {side:.3g} is not above twice the "
            f"largest diameter {diameters.max():.3g}; use more particles or a lower phi"
        )
    if diameters.max() >= side:
        raise ValueError(f"too few particles for phi = {phi}: the container {side:.3g} is not "
                         f"wider than the largest diameter {diameters.max():.3g}")
    rng = np.random.default_rng(seed)
    n = diameters.shape[0]
    positions = rng.uniform(0.0, side, size=(n, d))
    radius = 0.5 * diameters
    for axis in boundaries.wall_axes:
        positions[:, axis] = radius + rng.uniform(0.0, 1.0, n) * (side - diameters)
    if boundaries.cylinder_axes:
        reach = 0.5 * (side - diameters) * np.sqrt(rng.uniform(0.0, 1.0, n))
        angle = rng.uniform(0.0, 2.0 * np.pi, n)
        a, b = boundaries.cylinder_axes
        positions[:, a] = 0.5 * side + reach * np.cos(angle)
        positions[:, b] = 0.5 * side + reach * np.sin(angle)
    return Packing(positions, diameters, np.full(d, side), boundaries).wrapped()


def start_of(diameters, d: int | None, start: Packing | None, *, phi: float, seed: int,
             boundaries: Boundaries | None = None, generator: str = "the generators",
             kinds: tuple[str, ...] = (PERIODIC,)) -> tuple[Packing, bool]:
    """The packing a generator starts from: `start`, or Poisson centres for `diameters`.

    Parameters
    ----------
    diameters : array_like, shape (N,), or None
        Diameters (length units); None, or the start's own, when `start` is given.
    d : int or None
        Dimension; None, or the start's own, when `start` is given.
    start : Packing or None
        A configuration to continue from.
    phi : float
        Packing fraction of the Poisson centres made when there is no `start`.
    seed : int
        Seed of those centres.
    boundaries : Boundaries, optional
        The container of those centres (default periodic); with `start`, None or the
        start's own.
    generator : str
        Name of the calling generator, for the messages.
    kinds : tuple of str
        The boundary kinds the generator handles (`calippso.geometry.boundaries.KINDS`); other
        containers are refused in one line.

    Returns
    -------
    Packing
        The start.
    bool
        Whether it was made here from `diameters` (True) or given (False).

    Raises
    ------
    ValueError
        When neither diameters and d nor `start` are given, they contradict each other, or
        the container is not one the generator handles.
    """
    if isinstance(diameters, Packing) and start is None:  # the calling style before start=
        warnings.warn("passing the start packing as the first argument is deprecated: pass "
                      "it as start=packing", DeprecationWarning, stacklevel=3)
        diameters, start = None, diameters
    if start is None:
        if diameters is None:
            raise ValueError("give diameters and d, or a start configuration as start=")
        boundaries = check_boundaries(boundaries, check_dimension(d), generator, kinds)
        return poisson(diameters, d, phi=phi, seed=seed, boundaries=boundaries), True
    if not isinstance(start, Packing):
        raise ValueError(f"start must be a calippso.Packing, got {type(start).__name__}")
    if boundaries is not None and boundaries != start.boundaries:
        raise ValueError(f"boundaries ({boundaries.describe()}) contradict the start's "
                         f"({start.boundaries.describe()}); give one or the other")
    check_boundaries(start.boundaries, start.d, generator, kinds)
    if d is not None and d != start.d:
        raise ValueError(f"d = {d} contradicts the start's dimension {start.d}")
    if diameters is not None and not np.array_equal(check_diameters(diameters), start.diameters):
        raise ValueError("diameters differ from the start's diameters; give one or the other")
    return start, False
