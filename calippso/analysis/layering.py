"""Layering next to a container's walls: the packing fraction against the distance from the
nearest wall.

The profile is a volume fraction: in the shell of points whose distance s from the wall lies
in a bin, the share of the volume inside the spheres (each sphere sliced exactly by the
shell's two surfaces; `calippso.analysis.slices`). It vanishes at the wall (a sphere touches
it at one point), oscillates over a few diameters as the spheres form layers, and tends to
the bulk packing fraction far from the wall; its mean over the shells, weighted by their
volumes, is the packing fraction φ of the whole packing. A number density of centres would
instead be a comb of peaks, and tends to the number density, not to φ.

The wall surfaces are those of `calippso.geometry.boundaries`: the planes at 0 and L_μ of each axis
with walls (s = min(x_μ, L_μ − x_μ)), and a cylinder's circle of radius L/2
(s = L/2 − the distance from its axis). With several of them, the shells at distance s from
each one are pooled (near an edge between two walls the shells of one cross those of the
other).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from ..geometry.boundaries import parse_axes
from ..geometry.packing import Packing, ball_volume
from ..result import JammingResult
from .slices import fraction_below, volume_inside_cylinder

__all__ = ["DEFAULT_BIN_WIDTH", "DensityProfile", "density_profile", "pooled_density_profile"]

#: Default bin width of the profile, in mean diameters.
DEFAULT_BIN_WIDTH = 0.05
#: Relative round-off forgiven when a width divides the container's half-width (no sliver
#: of a last bin).
_ROUND_OFF = 1e-9


class DensityProfile(NamedTuple):
    """Packing fraction against the distance from the nearest wall.

    Attributes
    ----------
    distance : ndarray, shape (B,)
        Bin centres: distance s from the wall, in mean diameters.
    phi : ndarray, shape (B,)
        Local packing fraction in each bin's shell (dimensionless).
    """

    distance: np.ndarray
    phi: np.ndarray


def _packing(item: Packing | JammingResult) -> Packing:
    if isinstance(item, JammingResult):
        return item.packing
    if isinstance(item, Packing):
        return item
    raise TypeError(f"expected a Packing or a JammingResult, got {type(item).__name__}")


def _surfaces(packing: Packing, axis) -> list[tuple[str, int]]:
    """The wall surfaces the profile is measured from: ("plane", μ) per walled axis and
    ("cylinder", first axis of its circle), all of them or those of `axis`."""
    boundaries = packing.boundaries
    every = [("plane", mu) for mu in boundaries.wall_axes]
    if boundaries.cylinder_axes:
        every.append(("cylinder", boundaries.cylinder_axes[0]))
    if not every:
        raise ValueError("the packing has no walls (periodic along every axis): a layering "
                         "profile needs flat walls or a cylinder")
    if axis is None:
        return every
    (mu,) = parse_axes(axis, packing.d)
    if mu in boundaries.wall_axes:
        return [("plane", mu)]
    if mu in boundaries.cylinder_axes:
        return [("cylinder", boundaries.cylinder_axes[0])]
    raise ValueError(f"axis {axis!r} has no wall ({boundaries.describe()})")


def _reach(packing: Packing, surface: tuple[str, int]) -> float:
    """The largest distance from that surface inside the container (length units)."""
    return 0.5 * float(packing.box[surface[1]])


def _plane_volumes(packing: Packing, axis: int, edges: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Sphere volume and shell volume in each bin of distance from the walls of `axis`."""
    x = packing.positions[:, axis]
    radius = 0.5 * packing.diameters
    volume = ball_volume(packing.d, radius)
    length = float(packing.box[axis])
    area = packing.volume / length                  # the wall's area
    below = np.zeros((edges.size,))
    for side in (x, length - x):                    # the wall at 0, then the wall at L
        below = below + volume @ fraction_below((edges[None, :] - side[:, None])
                                                / radius[:, None], packing.d)
    return np.diff(below), 2.0 * area * np.diff(edges)


def _cylinder_volumes(packing: Packing, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sphere volume and shell volume in each bin of distance from the cylinder's wall."""
    a, b = packing.boundaries.cylinder_axes
    outer = 0.5 * float(packing.box[a])
    offset = np.hypot(packing.positions[:, a] - outer, packing.positions[:, b] - outer)
    reach = outer - edges                           # radii of the bin edges, decreasing
    inside = volume_inside_cylinder(offset, 0.5 * packing.diameters, reach, packing.d).sum(0)
    length = packing.volume / (np.pi * outer ** 2)  # the measure along the cylinder's axis
    return -np.diff(inside), -np.diff(np.pi * reach ** 2) * length


def _volumes(packing: Packing, surfaces: list[tuple[str, int]], edges: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Sphere and shell volumes per bin, pooled over `surfaces`; `edges` in length units,
    each surface's bins clipped to its reach."""
    spheres = np.zeros(edges.size - 1)
    shells = np.zeros(edges.size - 1)
    for surface in surfaces:
        clipped = np.minimum(edges, _reach(packing, surface))
        kind, axis = surface
        sphere, shell = (_plane_volumes(packing, axis, clipped) if kind == "plane"
                         else _cylinder_volumes(packing, clipped))
        spheres += sphere
        shells += shell
    return spheres, shells


def _uniform_edges(width: float, largest: float) -> np.ndarray:
    """Edges `width` apart from 0 to `largest` (the last bin clipped there)."""
    count = max(1, int(np.ceil(largest / width * (1.0 - _ROUND_OFF))))
    return np.minimum(width * np.arange(count + 1), largest)


def _edges(bins, largest: float) -> np.ndarray:
    """Bin edges in mean diameters, from 0 to `largest`, as `density_profile` takes them."""
    if bins is None:
        return _uniform_edges(DEFAULT_BIN_WIDTH, largest)
    if np.ndim(bins) == 0:
        if int(bins) < 1:
            raise ValueError(f"bins must be a positive count or a sequence of edges, got {bins}")
        return np.linspace(0.0, largest, int(bins) + 1)
    edges = np.asarray(bins, dtype=np.float64)
    if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0) or edges[0] < 0:
        raise ValueError("bin edges must be an increasing sequence of distances ≥ 0")
    return edges


def _profile(spheres: np.ndarray, shells: np.ndarray, edges: np.ndarray) -> DensityProfile:
    with np.errstate(invalid="ignore", divide="ignore"):
        phi = np.where(shells > 0, spheres / shells, np.nan)
    return DensityProfile(0.5 * (edges[:-1] + edges[1:]), phi)


def density_profile(packing: Packing | JammingResult, axis: int | str | None = None,
                    bins: int | np.ndarray | None = None) -> DensityProfile:
    """Local packing fraction against the distance from the nearest wall.

    Parameters
    ----------
    packing : Packing or JammingResult
        A packing with flat walls or a cylinder (`calippso.geometry.boundaries`).
    axis : int or str, optional
        Measure from the walls of this axis only ("x", "y", … or a number; an axis of the
        cylinder means the cylinder). Default: every wall, pooled.
    bins : int or array_like, optional
        A number of equal bins from the wall to the container's middle, or the bin edges in
        mean diameters. Default: bins `DEFAULT_BIN_WIDTH` wide.

    Returns
    -------
    DensityProfile
        Bin centres (mean diameters) and the volume fraction in each bin's shell; NaN in a
        bin beyond the container's middle.

    Raises
    ------
    ValueError
        A periodic packing, or `axis` without walls.
    """
    packing = _packing(packing)
    surfaces = _surfaces(packing, axis)
    scale = packing.mean_diameter
    edges = _edges(bins, max(_reach(packing, s) for s in surfaces) / scale)
    return _profile(*_volumes(packing, surfaces, edges * scale), edges)


def pooled_density_profile(items: Iterable[Packing | JammingResult],
                           bin_width: float = DEFAULT_BIN_WIDTH) -> DensityProfile:
    """The layering profile of several packings, pooled: sphere volume over shell volume
    summed over them, in bins of `bin_width` mean diameters up to the smallest container's
    middle.

    Parameters
    ----------
    items : iterable of Packing or JammingResult
        Packings with walls (every wall of each, as `density_profile` with ``axis=None``).
    bin_width : float
        Bin width, in mean diameters (> 0).

    Returns
    -------
    DensityProfile
    """
    packings = [_packing(item) for item in items]
    if not packings:
        raise ValueError("no packing to pool")
    if not bin_width > 0:
        raise ValueError(f"bin_width must be positive, got {bin_width!r}")
    surfaces = [_surfaces(p, None) for p in packings]
    largest = min(max(_reach(p, s) for s in found) / p.mean_diameter
                  for p, found in zip(packings, surfaces))
    edges = _uniform_edges(bin_width, largest)
    spheres = np.zeros(edges.size - 1)
    shells = np.zeros(edges.size - 1)
    for packing, found in zip(packings, surfaces):
        sphere, shell = _volumes(packing, found, edges * packing.mean_diameter)
        spheres += sphere
        shells += shell
    return _profile(spheres, shells, edges)
