"""The walls of a container in the pictures of `calippso.reporting.render`: flat walls as
thick lines (d = 2) or tinted faces of the box (d = 3), a cylinder as its circle (d = 2) or
the circles at its two ends (d = 3), and the same in a POV-Ray scene.

matplotlib is imported only when a picture is drawn.
"""

from __future__ import annotations

import numpy as np

from ..geometry.packing import Packing

__all__ = ["WALL_COLOUR", "wall_key", "draw_walls_2d", "draw_walls_3d", "povray_walls"]

#: Colour of the walls, and its entry in the colour key.
WALL_COLOUR = (0.16, 0.32, 0.62)
#: Line width of the walls (points), and the opacity of the box faces that are walls (d = 3).
WALL_WIDTH, WALL_FACE_ALPHA = 3.0, 0.12
#: Points on a cylinder's drawn circle.
CIRCLE_POINTS = 181
#: POV-Ray: the walls' transmission (1: invisible) and thickness (units of the box diagonal).
POVRAY_WALL_TRANSMIT, POVRAY_WALL_THICKNESS = 0.8, 0.004


def wall_key(packing: Packing) -> list[tuple[str, tuple[float, float, float]]]:
    """The key entry of the walls ("walls in x", "cylinder in x, y"), or none."""
    boundaries = packing.boundaries
    if boundaries.is_periodic:
        return []
    described = "; ".join(part for part in boundaries.describe().split("; ")
                          if not part.startswith("periodic"))
    return [(described, WALL_COLOUR)]


def _circle(packing: Packing, level: float | None = None) -> np.ndarray:
    """Points of the cylinder's circle, shape (CIRCLE_POINTS, d); in d = 3 in the plane
    where the third axis is at `level`."""
    a, b = packing.boundaries.cylinder_axes
    radius = 0.5 * float(packing.box[a])
    angle = np.linspace(0.0, 2.0 * np.pi, CIRCLE_POINTS)
    points = np.zeros((CIRCLE_POINTS, packing.d))
    points[:, a] = radius * (1.0 + np.cos(angle))
    points[:, b] = radius * (1.0 + np.sin(angle))
    if level is not None:
        (other,) = set(range(packing.d)) - {a, b}
        points[:, other] = level
    return points


def draw_walls_2d(axis, packing: Packing, zorder: int) -> None:
    """Flat walls as thick lines on the box edges, a cylinder as its circle (d = 2)."""
    from matplotlib.collections import LineCollection

    box = packing.box
    segments = []
    for mu in packing.boundaries.wall_axes:
        other = 1 - mu
        for level in (0.0, box[mu]):
            ends = np.zeros((2, 2))
            ends[:, mu] = level
            ends[1, other] = box[other]
            segments.append(ends)
    if packing.boundaries.cylinder_axes:
        circle = _circle(packing)
        segments.extend(np.stack([circle[:-1], circle[1:]], axis=1))
    if segments:
        axis.add_collection(LineCollection(segments, colors=[WALL_COLOUR],
                                           linewidths=WALL_WIDTH, zorder=zorder))


def _faces(packing: Packing) -> list[np.ndarray]:
    """The box faces that are flat walls, each as its 4 corners, shape (4, 3)."""
    box = packing.box
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    faces = []
    for mu in packing.boundaries.wall_axes:
        others = [nu for nu in range(3) if nu != mu]
        for level in (0.0, box[mu]):
            corners = np.zeros((4, 3))
            corners[:, others] = square * box[others]
            corners[:, mu] = level
            faces.append(corners)
    return faces


def draw_walls_3d(axis, packing: Packing, basis: np.ndarray, behind: int, front: int) -> None:
    """Flat walls as tinted box faces, a cylinder as the circles at its two ends, projected
    along `basis[2]` (d = 3); those behind the box centre at z-order `behind`, the others at
    `front`."""
    from matplotlib.collections import LineCollection, PolyCollection

    centre = packing.box / 2
    for corners in _faces(packing):
        projected = (corners - centre) @ basis.T
        zorder = behind if projected[:, 2].mean() < 0 else front
        axis.add_collection(PolyCollection([projected[:, :2]], facecolors=[WALL_COLOUR],
                                           alpha=WALL_FACE_ALPHA, edgecolors="none",
                                           zorder=zorder))
        outline = np.vstack([projected[:, :2], projected[:1, :2]])
        axis.add_collection(LineCollection([outline], colors=[WALL_COLOUR],
                                           linewidths=WALL_WIDTH / 2, zorder=zorder))
    if packing.boundaries.cylinder_axes:
        (other,) = set(range(3)) - set(packing.boundaries.cylinder_axes)
        for level in (0.0, float(packing.box[other])):
            projected = (_circle(packing, level) - centre) @ basis.T
            zorder = behind if projected[:, 2].mean() < 0 else front
            axis.add_collection(LineCollection([projected[:, :2]], colors=[WALL_COLOUR],
                                               linewidths=WALL_WIDTH, zorder=zorder))


def povray_walls(packing: Packing) -> list[str]:
    """POV-Ray objects of the walls: a thin translucent slab outside each flat wall, an open
    translucent cylinder (d = 3)."""
    box = packing.box
    thickness = POVRAY_WALL_THICKNESS * float(np.linalg.norm(box))
    r, g, b = WALL_COLOUR
    pigment = f"pigment {{ rgbt <{r}, {g}, {b}, {POVRAY_WALL_TRANSMIT}> }}"
    lines = []
    for mu in packing.boundaries.wall_axes:
        for level, outward in ((0.0, -thickness), (float(box[mu]), thickness)):
            low, high = np.zeros(3), box.astype(float).copy()
            low[mu], high[mu] = sorted((level, level + outward))
            lines.append(f"box {{ <{low[0]}, {low[1]}, {low[2]}>, <{high[0]}, {high[1]}, "
                         f"{high[2]}> {pigment} }}")
    if packing.boundaries.cylinder_axes:
        a, b_axis = packing.boundaries.cylinder_axes
        (other,) = set(range(3)) - {a, b_axis}
        start, end = box / 2, box / 2           # two new arrays
        start[other], end[other] = 0.0, box[other]
        lines.append(f"cylinder {{ <{start[0]}, {start[1]}, {start[2]}>, <{end[0]}, {end[1]}, "
                     f"{end[2]}>, {0.5 * box[a]} open {pigment} }}")
    return lines
