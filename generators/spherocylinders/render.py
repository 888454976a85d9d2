"""Pictures of spherocylinder packings: POV-Ray when installed, matplotlib otherwise.

Both backends draw the particles whose centres lie in the box (parts may stick out of the
box outline), seen obliquely, coloured by orientation (|u_x|, |u_y|, |u_z| as red, green,
blue, so aligned domains share a colour) or by species, under a title and above a colour
key. The view, the box outline, the frame and the POV-Ray run are those of the sphere
pictures (`calippso.reporting.render`), imported when a picture is drawn.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np

from .packing import SpherocylinderPacking

__all__ = ["render"]

#: Colour of a particle whose axis is exactly along x, y or z (orientation colouring).
_AXIS_KEY = (("axis ∥ x", 0), ("axis ∥ y", 1), ("axis ∥ z", 2))
#: Colour = _FLOOR + (1 − _FLOOR) |u| (no component black).
_FLOOR = 0.15


def _colours(packing: SpherocylinderPacking, colour_by: str, species_colours: np.ndarray
             ) -> tuple[np.ndarray, list[tuple[str, tuple[float, float, float]]]]:
    """Colours of the particles, shape (N, 3), and the colour key that explains them."""
    if colour_by == "orientation":
        key = [(label, tuple(_FLOOR + (1 - _FLOOR) * np.eye(3)[axis])) for label, axis in _AXIS_KEY]
        return _FLOOR + (1 - _FLOOR) * np.abs(packing.axes), key
    if colour_by == "species":
        shapes = np.round(np.column_stack([packing.diameters, packing.lengths]), 12)
        kinds, index = np.unique(shapes, axis=0, return_inverse=True)
        palette = species_colours[np.arange(len(kinds)) % len(species_colours)]
        key = [(f"d = {d:.4g}, l = {length:.4g}", tuple(colour))
               for (d, length), colour in zip(kinds, palette)]
        return palette[index.ravel()], key
    raise ValueError(f"colour_by must be 'orientation' or 'species', got {colour_by!r}")


def _title(packing: SpherocylinderPacking) -> str:
    return (f"{packing.n} spherocylinders, φ = {packing.phi:.4f}, "
            f"nematic order S = {packing.nematic_order():.3f}")


def render(packing: SpherocylinderPacking, path: str | PathLike, *, backend: str = "auto",
           size: int = 900, colour_by: str = "orientation", elevation: float = 25.0,
           azimuth: float = 35.0, title: str | None = None, timeout: float = 600.0) -> Path:
    """Render a packing to a PNG picture with a title, a colour key and the box outline.

    Parameters
    ----------
    packing : SpherocylinderPacking
    path : str or path-like
        Output PNG.
    backend : {"auto", "povray", "matplotlib"}
        "auto" uses POV-Ray (ray-traced, the look of Bargiel's figures) when the ``povray``
        program is on the PATH, matplotlib (depth-sorted capsules, no ray tracing) otherwise.
    size : int
        Picture width and height in pixels.
    colour_by : {"orientation", "species"}
    elevation, azimuth : float
        Viewing direction, in degrees.
    title : str, optional
        Picture title (default: N, φ and the nematic order).
    timeout : float
        Seconds allowed to POV-Ray.

    Returns
    -------
    Path
        The PNG written.

    Raises
    ------
    ValueError
        For an unknown backend or colouring, or "povray" requested but not installed.
    """
    from calippso.reporting import render as frame

    path = Path(path)
    colours, key = _colours(packing, colour_by, frame.SPECIES_COLOURS)
    backend = frame.choose_backend(backend, 3)
    title = _title(packing) if title is None else title
    packing = packing.wrapped()
    if backend == "povray":
        lines = frame.povray_scene(packing.box, elevation, azimuth) + _povray_particles(
            packing, colours)
        return frame.render_povray(lines, path, size, title, key, timeout)
    figure, axis = frame.framed_figure(size, title, key)
    basis = frame.view_basis(elevation, azimuth)
    _draw_capsules(axis, packing, colours, basis, frame.VIEW_HALF_WIDTH)
    frame.draw_box_outline(axis, packing.box, basis, behind=1, front=3)
    return frame.save_figure(figure, path)


def _povray_particles(packing: SpherocylinderPacking, colours: np.ndarray) -> list[str]:
    """One POV-Ray object per particle (a sphere where the cylinder has no length)."""
    lines = ["#macro SC(A, B, R, C) merge { cylinder { A, B, R } sphere { A, R } sphere { B, R } "
             "pigment { rgb C } finish { F } } #end",
             "#macro SP(A, R, C) sphere { A, R pigment { rgb C } finish { F } } #end"]
    half = packing.lengths / 2
    for r, u, d, h, c in zip(packing.positions, packing.axes, packing.diameters, half, colours):
        colour = f"<{c[0]:.4f}, {c[1]:.4f}, {c[2]:.4f}>"
        if h > 1e-9 * d:
            a, b = r - h * u, r + h * u
            lines.append(f"SC(<{a[0]:.6f}, {a[1]:.6f}, {a[2]:.6f}>, "
                         f"<{b[0]:.6f}, {b[1]:.6f}, {b[2]:.6f}>, {d / 2:.6f}, {colour})")
        else:
            lines.append(f"SP(<{r[0]:.6f}, {r[1]:.6f}, {r[2]:.6f}>, {d / 2:.6f}, {colour})")
    return lines


def _draw_capsules(axis, packing: SpherocylinderPacking, colours: np.ndarray,
                   basis: np.ndarray, half_width: float) -> None:
    """Capsules as round-capped lines (dark rim, shaded core), drawn back to front."""
    from matplotlib.collections import LineCollection

    projected = (packing.positions - packing.box / 2) @ basis.T  # screen x, screen y, depth
    axes_projected = packing.axes @ basis.T
    half = packing.lengths / 2
    extent = half_width * float(np.linalg.norm(packing.box))
    axis.set_xlim(-extent, extent)
    axis.set_ylim(-extent, extent)
    # the square of side 2 extent fills the shorter side of the axes (equal aspect)
    region = axis.get_position()
    width, height = axis.figure.get_size_inches()
    points_per_unit = min(region.width * width, region.height * height) * 72 / (2 * extent)
    depth = projected[:, 2]
    shade = 0.55 + 0.45 * (depth - depth.min()) / max(np.ptp(depth), 1e-12)
    segments, widths, line_colours = [], [], []
    for i in np.argsort(depth):  # back to front
        tip = half[i] * axes_projected[i, :2] + [1e-6 * packing.diameters[i], 0.0]
        segment = [projected[i, :2] - tip, projected[i, :2] + tip]
        width = packing.diameters[i] * points_per_unit
        segments += [segment, segment]
        widths += [width, 0.82 * width]
        line_colours += [(0.1, 0.1, 0.1), tuple(np.clip(colours[i] * shade[i], 0, 1))]
    axis.add_collection(LineCollection(segments, linewidths=widths, colors=line_colours,
                                       capstyle="round", zorder=2))
