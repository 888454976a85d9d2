"""Pictures of spherocylinder packings: POV-Ray when installed, matplotlib otherwise.

Both backends draw the particles whose centres lie in the box (parts may stick out), seen
obliquely, coloured by orientation (|u_x|, |u_y|, |u_z| as red, green, blue, so aligned
domains share a colour) or by species.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from os import PathLike
from pathlib import Path

import numpy as np

from .packing import SpherocylinderPacking

__all__ = ["render"]

_SPECIES_COLOURS = np.array([[0.85, 0.33, 0.10], [0.00, 0.45, 0.74], [0.47, 0.67, 0.19],
                             [0.49, 0.18, 0.56], [0.93, 0.69, 0.13]])


def _colours(packing: SpherocylinderPacking, colour_by: str) -> np.ndarray:
    if colour_by == "orientation":
        return 0.15 + 0.85 * np.abs(packing.axes)
    if colour_by == "species":
        shapes = np.round(np.column_stack([packing.diameters, packing.lengths]), 12)
        _, index = np.unique(shapes, axis=0, return_inverse=True)
        return _SPECIES_COLOURS[index.ravel() % len(_SPECIES_COLOURS)]
    raise ValueError(f"colour_by must be 'orientation' or 'species', got {colour_by!r}")


def _view_basis(elevation: float, azimuth: float) -> np.ndarray:
    """Rows: screen right, screen up, towards the viewer (orthonormal)."""
    el, az = np.radians(elevation), np.radians(azimuth)
    towards = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    right = np.cross([0.0, 0.0, 1.0], towards)
    right /= np.linalg.norm(right)
    return np.array([right, np.cross(towards, right), towards])


def render(packing: SpherocylinderPacking, path: str | PathLike, *, backend: str = "auto",
           size: int = 900, colour_by: str = "orientation", elevation: float = 25.0,
           azimuth: float = 35.0, timeout: float = 600.0) -> Path:
    """Render a packing to a PNG picture.

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
    path = Path(path)
    colours = _colours(packing, colour_by)
    packing = packing.wrapped()
    if backend == "auto":
        backend = "povray" if shutil.which("povray") else "matplotlib"
    if backend == "povray":
        if shutil.which("povray") is None:
            raise ValueError("backend 'povray' requested but the povray program is not installed "
                             "(Debian: apt install povray); use backend='matplotlib'")
        _render_povray(packing, colours, path, size, elevation, azimuth, timeout)
    elif backend == "matplotlib":
        _render_matplotlib(packing, colours, path, size, elevation, azimuth)
    else:
        raise ValueError(f"backend must be 'auto', 'povray' or 'matplotlib', got {backend!r}")
    return path


def _render_povray(packing, colours, path, size, elevation, azimuth, timeout) -> None:
    basis = _view_basis(elevation, azimuth)
    centre = packing.box / 2
    extent = float(np.linalg.norm(packing.box))
    camera = centre + basis[2] * 3.0 * extent
    lines = [
        "#version 3.7;",
        "global_settings { assumed_gamma 1.0 }",
        "background { rgb <1, 1, 1> }",
        f"camera {{ orthographic location <{camera[0]}, {camera[1]}, {camera[2]}> "
        f"look_at <{centre[0]}, {centre[1]}, {centre[2]}> sky <0, 0, 1> right x*{1.05 * extent} "
        f"up y*{1.05 * extent} }}",
        f"light_source {{ <{camera[0] + extent}, {camera[1] - extent}, {camera[2] + 2 * extent}>"
        " rgb 1.0 }",
        f"light_source {{ <{camera[0]}, {camera[1]}, {camera[2]}> rgb 0.45 shadowless }}",
        "#declare F = finish { ambient 0.12 diffuse 0.75 specular 0.35 roughness 0.02 };",
        "#macro SC(A, B, R, C) merge { cylinder { A, B, R } sphere { A, R } sphere { B, R } "
        "pigment { rgb C } finish { F } } #end",
        "#macro SP(A, R, C) sphere { A, R pigment { rgb C } finish { F } } #end",
    ]
    half = packing.lengths / 2
    for r, u, d, h, c in zip(packing.positions, packing.axes, packing.diameters, half, colours):
        colour = f"<{c[0]:.4f}, {c[1]:.4f}, {c[2]:.4f}>"
        if h > 1e-9 * d:
            a, b = r - h * u, r + h * u
            lines.append(f"SC(<{a[0]:.6f}, {a[1]:.6f}, {a[2]:.6f}>, "
                         f"<{b[0]:.6f}, {b[1]:.6f}, {b[2]:.6f}>, {d / 2:.6f}, {colour})")
        else:
            lines.append(f"SP(<{r[0]:.6f}, {r[1]:.6f}, {r[2]:.6f}>, {d / 2:.6f}, {colour})")
    with tempfile.TemporaryDirectory() as folder:
        scene = Path(folder) / "scene.pov"
        scene.write_text("\n".join(lines) + "\n", encoding="utf-8")
        output = Path(folder) / "scene.png"
        command = ["povray", f"+I{scene}", f"+O{output}", f"+W{size}", f"+H{size}", "+FN",
                   "+A0.3", "-D", "-V", "+WL0"]
        completed = subprocess.run(command, capture_output=True, text=True, timeout=timeout,
                                   cwd=folder)
        if completed.returncode != 0 or not output.exists():
            raise RuntimeError(f"povray failed ({completed.returncode}): "
                               f"{completed.stderr[-2000:]}")
        shutil.copyfile(output, path)


def _render_matplotlib(packing, colours, path, size, elevation, azimuth) -> None:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    basis = _view_basis(elevation, azimuth)
    centre = packing.box / 2
    projected = (packing.positions - centre) @ basis.T  # (N, 3): screen x, screen y, depth
    axes_projected = packing.axes @ basis.T
    half = packing.lengths / 2
    extent = 0.55 * float(np.linalg.norm(packing.box))
    dpi = 100
    figure = plt.figure(figsize=(size / dpi, size / dpi), dpi=dpi)
    axis = figure.add_axes((0, 0, 1, 1))
    axis.set_xlim(-extent, extent)
    axis.set_ylim(-extent, extent)
    axis.set_axis_off()
    points_per_unit = size / dpi * 72 / (2 * extent)
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
                                       capstyle="round"))
    figure.savefig(path, dpi=dpi, facecolor="white")
    plt.close(figure)
