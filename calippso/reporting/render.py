"""Pictures of packings: spheres and disks, and what the spherocylinder pictures
(`generators.spherocylinders.render`) share with them.

Every picture has a title, a colour key and the outline of the box, and the walls of a
container (`calippso.reporting.containers`). matplotlib draws disks (d = 2; particles cut by
a periodic box edge also show at the opposite edge) and, where
POV-Ray is not installed, spheres (d = 3) as depth-sorted discs shaded by depth, seen
obliquely. POV-Ray, when the ``povray`` program is on the PATH, ray-traces d = 3 pictures;
matplotlib then adds the title and the key around them. In d = 3 the particles whose centres
lie in the box are drawn (parts may stick out of the outline).

matplotlib (the extra ``plot``) is imported only when a picture is drawn; this module never
imports numba.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from os import PathLike
from pathlib import Path

import numpy as np

from ..geometry.packing import Packing
from .containers import draw_walls_2d, draw_walls_3d, povray_walls, wall_key

__all__ = ["BACKENDS", "render_spheres", "sphere_colours", "sphere_title", "view_basis",
           "box_edges", "choose_backend", "framed_figure", "save_figure", "draw_box_outline",
           "povray_scene", "render_povray"]

#: Picture backends: "auto" is POV-Ray in d = 3 when installed, matplotlib otherwise.
BACKENDS = ("auto", "povray", "matplotlib")
#: Colours of the particle kinds (species), in order.
SPECIES_COLOURS = np.array([[0.85, 0.33, 0.10], [0.00, 0.45, 0.74], [0.47, 0.67, 0.19],
                            [0.49, 0.18, 0.56], [0.93, 0.69, 0.13]])
#: Distinct diameters up to which spheres get one colour each; a more polydisperse packing
#: is coloured by diameter on `DIAMETER_COLOURMAP` (the key then shows a few diameters).
MAX_SPECIES = len(SPECIES_COLOURS)
DIAMETER_COLOURMAP = "viridis"
#: Diameters shown in the key of a packing coloured by diameter (quantiles).
DIAMETER_KEY_QUANTILES = (0.0, 0.5, 1.0)
#: Colour of rattlers, when the picture knows them (a jammed result).
RATTLER_COLOUR = (0.80, 0.80, 0.80)
#: Colour of the box outline and of the particle rims.
OUTLINE_COLOUR = (0.12, 0.12, 0.12)
#: Shares of the picture height kept for the title (top) and the colour key (bottom).
TITLE_BAND, KEY_BAND = 0.07, 0.09
#: Dots per inch of the pictures (the size is given in pixels).
DPI = 100
#: Half-width of the oblique view, in units of the box diagonal (the whole box fits).
VIEW_HALF_WIDTH = 0.55
#: Radius of the POV-Ray box edges, in units of the box diagonal.
POVRAY_EDGE_RADIUS = 0.002

#: A colour key: (label, RGB colour) per entry.
Key = list[tuple[str, tuple[float, float, float]]]


# ----------------------------------------------------------------------------- shared parts

def view_basis(elevation: float, azimuth: float) -> np.ndarray:
    """Rows: screen right, screen up, towards the viewer (orthonormal); angles in degrees."""
    el, az = np.radians(elevation), np.radians(azimuth)
    towards = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    right = np.cross([0.0, 0.0, 1.0], towards)
    right /= np.linalg.norm(right)
    return np.array([right, np.cross(towards, right), towards])


def box_edges(box: np.ndarray) -> np.ndarray:
    """The 12 edges of the box [0, L_x] × [0, L_y] × [0, L_z], shape (12, 2, 3)."""
    box = np.asarray(box, dtype=np.float64)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    pairs = [(a, b) for a in range(8) for b in range(a + 1, 8)
             if np.count_nonzero(corners[a] != corners[b]) == 1]
    return np.array([[corners[a] * box, corners[b] * box] for a, b in pairs])


def choose_backend(backend: str, d: int) -> str:
    """The backend that draws a picture in dimension `d`: "povray" or "matplotlib".

    Raises
    ------
    ValueError
        An unknown backend, "povray" for d = 2, or "povray" when it is not installed.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    installed = shutil.which("povray") is not None
    if backend == "auto":
        return "povray" if installed and d == 3 else "matplotlib"
    if backend == "povray" and d != 3:
        raise ValueError(f"POV-Ray draws d = 3 pictures, this packing has d = {d}: use "
                         "backend 'matplotlib'")
    if backend == "povray" and not installed:
        raise ValueError("backend 'povray' requested but the povray program is not installed "
                         "(Debian: apt install povray); use backend 'matplotlib'")
    return backend


def framed_figure(size: int, title: str, key: Key):
    """A `size` × `size` pixel figure with `title` on top and `key` below; return it and the
    (axis-free, equal-aspect) axes for the picture between them."""
    from ._matplotlib import pyplot

    figure = pyplot().figure(figsize=(size / DPI, size / DPI), dpi=DPI, facecolor="white")
    axis = figure.add_axes((0.0, KEY_BAND, 1.0, 1.0 - KEY_BAND - TITLE_BAND))
    axis.set_axis_off()
    axis.set_aspect("equal")
    points = size / DPI * 72  # picture height in points
    figure.text(0.5, 1.0 - TITLE_BAND / 2, title, ha="center", va="center",
                fontsize=min(12.0, 0.028 * points))
    if key:
        from matplotlib.patches import Patch

        handles = [Patch(facecolor=colour, edgecolor=OUTLINE_COLOUR, label=label)
                   for label, colour in key]
        figure.legend(handles=handles, loc="center", bbox_to_anchor=(0.5, KEY_BAND / 2),
                      ncol=min(len(handles), 4), frameon=False,
                      fontsize=min(10.0, 0.022 * points), handlelength=1.2,
                      columnspacing=1.0)
    return figure, axis


def save_figure(figure, path: Path) -> Path:
    """Write `figure` as a PNG of its own pixel size and close it."""
    from ._matplotlib import pyplot

    figure.savefig(path, dpi=DPI, facecolor="white")
    pyplot().close(figure)
    return path


def draw_box_outline(axis, box: np.ndarray, basis: np.ndarray, behind: int, front: int) -> None:
    """The projected box edges: those behind the box centre at z-order `behind`, the others
    at `front` (draw the particles in between)."""
    from matplotlib.collections import LineCollection

    edges = (box_edges(box) - np.asarray(box) / 2) @ basis.T
    depth = edges[:, :, 2].mean(axis=1)
    for chosen, zorder in ((depth < 0, behind), (depth >= 0, front)):
        axis.add_collection(LineCollection(edges[chosen, :, :2], colors=[OUTLINE_COLOUR],
                                           linewidths=1.0, zorder=zorder))


def povray_scene(box: np.ndarray, elevation: float, azimuth: float) -> list[str]:
    """The start of a POV-Ray scene: camera, lights, the finish ``F`` and the box edges."""
    box = np.asarray(box, dtype=np.float64)
    basis = view_basis(elevation, azimuth)
    centre = box / 2
    extent = float(np.linalg.norm(box))
    camera = centre + basis[2] * 3.0 * extent
    radius = POVRAY_EDGE_RADIUS * extent
    lines = [
        "#version 3.7;",
        "global_settings { assumed_gamma 1.0 }",
        "background { rgb <1, 1, 1> }",
        f"camera {{ orthographic location <{camera[0]}, {camera[1]}, {camera[2]}> "
        f"look_at <{centre[0]}, {centre[1]}, {centre[2]}> sky <0, 0, 1> "
        f"right x*{2 * VIEW_HALF_WIDTH * extent} up y*{2 * VIEW_HALF_WIDTH * extent} }}",
        f"light_source {{ <{camera[0] + extent}, {camera[1] - extent}, {camera[2] + 2 * extent}>"
        " rgb 1.0 }",
        f"light_source {{ <{camera[0]}, {camera[1]}, {camera[2]}> rgb 0.45 shadowless }}",
        "#declare F = finish { ambient 0.12 diffuse 0.75 specular 0.35 roughness 0.02 };",
    ]
    edge = OUTLINE_COLOUR
    for a, b in box_edges(box):
        lines.append(f"cylinder {{ <{a[0]}, {a[1]}, {a[2]}>, <{b[0]}, {b[1]}, {b[2]}>, {radius} "
                     f"pigment {{ rgb <{edge[0]}, {edge[1]}, {edge[2]}> }} }}")
    return lines


def render_povray(lines: list[str], path: Path, size: int, title: str, key: Key,
                  timeout: float) -> Path:
    """Ray-trace the scene `lines` with POV-Ray and frame it with `title` and `key`.

    Without matplotlib the bare POV-Ray picture is written (no title or key).

    Raises
    ------
    RuntimeError
        POV-Ray failed (its last messages are quoted).
    """
    with tempfile.TemporaryDirectory() as folder:
        scene, picture = Path(folder) / "scene.pov", Path(folder) / "scene.png"
        scene.write_text("\n".join(lines) + "\n", encoding="utf-8")
        command = ["povray", f"+I{scene}", f"+O{picture}", f"+W{size}", f"+H{size}", "+FN",
                   "+A0.3", "-D", "-V", "+WL0"]
        completed = subprocess.run(command, capture_output=True, text=True, timeout=timeout,
                                   cwd=folder)
        if completed.returncode != 0 or not picture.exists():
            raise RuntimeError(f"povray failed ({completed.returncode}): "
                               f"{' '.join(completed.stderr[-2000:].split())}")
        try:
            import matplotlib.image
        except ImportError:
            shutil.copyfile(picture, path)
            return path
        figure, axis = framed_figure(size, title, key)
        axis.imshow(matplotlib.image.imread(picture), interpolation="antialiased")
        return save_figure(figure, path)


# ----------------------------------------------------------------------------- spheres

def sphere_colours(packing: Packing, rattlers: np.ndarray | None = None
                   ) -> tuple[np.ndarray, Key]:
    """Colours of the particles, shape (N, 3), and the key that explains them.

    One colour per diameter for up to `MAX_SPECIES` distinct diameters, else a colour
    scale over the diameters (the key shows the smallest, median and largest); rattlers,
    when given, in `RATTLER_COLOUR`.
    """
    diameters = packing.diameters
    sizes, index = np.unique(np.round(diameters, 12), return_inverse=True)
    if sizes.size <= MAX_SPECIES:
        colours = SPECIES_COLOURS[index.ravel()]
        key = [(f"σ = {size:.4g}", tuple(SPECIES_COLOURS[k])) for k, size in enumerate(sizes)]
    else:
        from matplotlib import colormaps

        scale = colormaps[DIAMETER_COLOURMAP]
        low, high = float(diameters.min()), float(diameters.max())
        colours = scale((diameters - low) / (high - low))[:, :3]
        shown = np.quantile(diameters, DIAMETER_KEY_QUANTILES)
        key = [(f"σ = {size:.4g}", tuple(scale((size - low) / (high - low))[:3]))
               for size in shown]
    if rattlers is not None and np.any(rattlers):
        colours = colours.copy()
        colours[np.asarray(rattlers, dtype=bool)] = RATTLER_COLOUR
        key.append(("rattler", RATTLER_COLOUR))
    return colours, key


def sphere_title(packing: Packing, rattlers: np.ndarray | None = None) -> str:
    """"N spheres (disks), d = …, φ = …" and the rattler count when it is known."""
    kind = "disks" if packing.d == 2 else "spheres"
    title = f"{packing.n} {kind}, d = {packing.d}, φ = {packing.phi:.4f}"
    if rattlers is not None:
        title += f", {int(np.count_nonzero(rattlers))} rattlers"
    return title


def render_spheres(packing: Packing, path: str | PathLike, *,
                   rattlers: np.ndarray | None = None, backend: str = "auto", size: int = 900,
                   elevation: float = 25.0, azimuth: float = 35.0, title: str | None = None,
                   timeout: float = 600.0) -> Path:
    """Draw a packing of disks (d = 2) or spheres (d = 3) as a PNG picture.

    Parameters
    ----------
    packing : Packing
    path : str or path-like
        Output PNG.
    rattlers : ndarray of bool, shape (N,), optional
        Rattlers (`JammingResult.rattlers`), drawn in grey.
    backend : {"auto", "povray", "matplotlib"}
        "auto": POV-Ray for spheres when the ``povray`` program is installed, matplotlib
        otherwise (always for disks).
    size : int
        Picture width and height in pixels.
    elevation, azimuth : float
        Viewing direction of a d = 3 picture, in degrees.
    title : str, optional
        Picture title (default: `sphere_title`).
    timeout : float
        Seconds allowed to POV-Ray.

    Returns
    -------
    Path
        The PNG written.

    Raises
    ------
    ValueError
        d is not 2 or 3, an unknown backend, or "povray" not installed or asked for disks.
    ImportError
        matplotlib is missing where it draws the picture.
    """
    if packing.d not in (2, 3):
        raise ValueError(f"render draws packings in d = 2 or 3, this one has d = {packing.d}")
    path = Path(path)
    backend = choose_backend(backend, packing.d)
    packing = packing.wrapped()
    colours, key = sphere_colours(packing, rattlers)
    key += wall_key(packing)
    title = sphere_title(packing, rattlers) if title is None else title
    if backend == "povray":
        lines = povray_scene(packing.box, elevation, azimuth) + povray_walls(packing) + [
            f"sphere {{ <{r[0]:.6f}, {r[1]:.6f}, {r[2]:.6f}>, {sigma / 2:.6f} "
            f"pigment {{ rgb <{c[0]:.4f}, {c[1]:.4f}, {c[2]:.4f}> }} finish {{ F }} }}"
            for r, sigma, c in zip(packing.positions, packing.diameters, colours)]
        return render_povray(lines, path, size, title, key, timeout)
    figure, axis = framed_figure(size, title, key)
    if packing.d == 2:
        _draw_disks(axis, packing, colours)
    else:
        _draw_spheres(axis, packing, colours, view_basis(elevation, azimuth))
    return save_figure(figure, path)


def _periodic_images(packing: Packing) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the disks and of their images across the periodic edges that reach into
    the box, with the index of the disk each one shows."""
    steps = [(-1, 0, 1) if periodic else (0,) for periodic in packing.periodic]
    shifts = np.array([[a, b] for a in steps[0] for b in steps[1]], dtype=float)
    radius = packing.diameters[:, None] / 2
    centres, owners = [], []
    for shift in shifts:
        moved = packing.positions + shift * packing.box
        inside = np.all((moved > -radius) & (moved < packing.box + radius), axis=1)
        centres.append(moved[inside])
        owners.append(np.flatnonzero(inside))
    return np.concatenate(centres), np.concatenate(owners)


def _draw_disks(axis, packing: Packing, colours: np.ndarray) -> None:
    """Disks in the box, cut by its edges (their images show at the opposite edges)."""
    from matplotlib.collections import EllipseCollection
    from matplotlib.patches import Rectangle

    centres, owners = _periodic_images(packing)
    sigma = packing.diameters[owners]
    disks = EllipseCollection(sigma, sigma, np.zeros(owners.size), units="xy", offsets=centres,
                              offset_transform=axis.transData, facecolors=colours[owners],
                              edgecolors=[OUTLINE_COLOUR], linewidths=0.4, zorder=2)
    outline = Rectangle((0.0, 0.0), *packing.box, fill=False, edgecolor=OUTLINE_COLOUR,
                        linewidth=1.2, zorder=3)
    axis.add_collection(disks)
    axis.add_patch(outline)
    disks.set_clip_path(outline)
    draw_walls_2d(axis, packing, zorder=4)
    margin = 0.02 * float(packing.box.max())
    axis.set_xlim(-margin, packing.box[0] + margin)
    axis.set_ylim(-margin, packing.box[1] + margin)


def _draw_spheres(axis, packing: Packing, colours: np.ndarray, basis: np.ndarray) -> None:
    """Spheres seen along `basis[2]`: discs drawn back to front, darker further away."""
    from matplotlib.collections import EllipseCollection

    projected = (packing.positions - packing.box / 2) @ basis.T
    depth = projected[:, 2]
    order = np.argsort(depth)
    shade = 0.55 + 0.45 * (depth - depth.min()) / max(np.ptp(depth), 1e-12)
    sigma = packing.diameters[order]
    axis.add_collection(EllipseCollection(
        sigma, sigma, np.zeros(packing.n), units="xy", offsets=projected[order, :2],
        offset_transform=axis.transData,
        facecolors=np.clip(colours[order] * shade[order, None], 0, 1),
        edgecolors=[OUTLINE_COLOUR], linewidths=0.3, zorder=2))
    draw_box_outline(axis, packing.box, basis, behind=1, front=3)
    draw_walls_3d(axis, packing, basis, behind=1, front=3)
    extent = VIEW_HALF_WIDTH * float(np.linalg.norm(packing.box))
    axis.set_xlim(-extent, extent)
    axis.set_ylim(-extent, extent)
