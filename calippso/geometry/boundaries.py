"""The boundaries of a packing's box: each axis periodic, between two flat hard walls, or one
of the two axes of a cylinder.

`Boundaries` is one small value that every layer reads (`Packing.boundaries`). It holds one
kind per axis:

* ``"periodic"``: the box repeats along the axis (the default, and the only kind before
  containers existed);
* ``"walls"``: two flat hard walls at 0 and L_μ; a centre x lies in [σ/2, L_μ − σ/2];
* ``"cylinder"``: exactly two axes, with equal sides L, hold a circle of diameter L inscribed
  in the box (centred at L/2 on both); a centre lies at most (L − σ)/2 from the circle's axis.

Coordinates follow PackingGeneration: a bounded axis runs from 0 to L, and the minimum image
applies along the periodic axes only (`Boundaries.periodic`). This module imports numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import pi

import numpy as np

__all__ = ["Boundaries", "KINDS", "PERIODIC", "WALLS", "CYLINDER", "INSIDE_TOLERANCE",
           "AXIS_NAMES", "BOUNDED_PADDING"]

PERIODIC = "periodic"
WALLS = "walls"
CYLINDER = "cylinder"
#: The kinds an axis can have.
KINDS = (PERIODIC, WALLS, CYLINDER)
#: A particle may cross its container's wall by at most this fraction of its diameter
#: (round-off); more is refused as a particle outside the container.
INSIDE_TOLERANCE = 1e-9
#: A box matrix in a container is padded along its bounded axes by this factor for the
#: lattice searches (`Boundaries.search_cell`): a centre lies within [0, L] there, so no
#: pair is closer than (BOUNDED_PADDING − 1) L through the padded axis, and no image across
#: it is ever found.
BOUNDED_PADDING = 3.0
#: Names of the first axes, for messages (further axes are numbered).
AXIS_NAMES = ("x", "y", "z", "w")


def axis_name(axis: int) -> str:
    """'x', 'y', 'z', 'w', then 'axis 4', 'axis 5', ..."""
    return AXIS_NAMES[axis] if axis < len(AXIS_NAMES) else f"axis {axis}"


def parse_axes(axes, d: int) -> tuple[int, ...]:
    """Axis indices from ints or names ("x", "y", ...), each in [0, d), no repeats."""
    if isinstance(axes, (str, int, np.integer)):
        axes = [axes]
    parsed = []
    for axis in axes:
        if isinstance(axis, str):
            name = axis.strip().lower()
            if name not in AXIS_NAMES[:d]:
                raise ValueError(f"unknown axis {axis!r}: in d = {d} the axes are "
                                 f"{', '.join(AXIS_NAMES[:d]) or 'numbered'} or 0..{d - 1}")
            axis = AXIS_NAMES.index(name)
        axis = int(axis)
        if not 0 <= axis < d:
            raise ValueError(f"axis {axis} is out of range for d = {d}")
        if axis in parsed:
            raise ValueError(f"axis {axis_name(axis)} is given twice")
        parsed.append(axis)
    return tuple(parsed)


@dataclass(frozen=True)
class Boundaries:
    """How the box is closed along each axis.

    Parameters
    ----------
    kinds : sequence of str, length d
        One of `KINDS` per axis; ``"cylinder"`` on exactly two axes or none.

    Raises
    ------
    ValueError
        An unknown kind, no axis, or a cylinder on other than two axes.
    """

    kinds: tuple[str, ...]

    def __post_init__(self) -> None:
        kinds = (self.kinds,) if isinstance(self.kinds, str) else tuple(self.kinds)
        if not kinds:
            raise ValueError("boundaries need one kind per axis, got none")
        unknown = sorted({kind for kind in kinds if kind not in KINDS})
        if unknown:
            raise ValueError(f"unknown boundary kind(s) {unknown}: choose among "
                             f"{', '.join(KINDS)}")
        n_cylinder = kinds.count(CYLINDER)
        if n_cylinder not in (0, 2):
            raise ValueError(f"a cylinder takes exactly two axes, got {n_cylinder}")
        object.__setattr__(self, "kinds", kinds)

    # ------------------------------------------------------------------ makers
    @classmethod
    def all_periodic(cls, d: int) -> "Boundaries":
        """Periodic along every one of the d axes (the default)."""
        return cls((PERIODIC,) * d)

    @classmethod
    def walls(cls, d: int, axes) -> "Boundaries":
        """Flat hard walls at 0 and L along `axes` (ints or "x", "y", ...), periodic elsewhere."""
        chosen = parse_axes(axes, d)
        return cls(tuple(WALLS if axis in chosen else PERIODIC for axis in range(d)))

    @classmethod
    def cylinder(cls, d: int, axes) -> "Boundaries":
        """A circle inscribed in the box in the plane of the two `axes`, periodic elsewhere."""
        chosen = parse_axes(axes, d)
        if len(chosen) != 2:
            raise ValueError(f"a cylinder takes exactly two axes, got {len(chosen)}")
        return cls(tuple(CYLINDER if axis in chosen else PERIODIC for axis in range(d)))

    @classmethod
    def from_text(cls, text: str) -> "Boundaries":
        """The inverse of `str`: kinds separated by spaces (what the files store)."""
        return cls(tuple(str(text).split()))

    def __str__(self) -> str:
        return " ".join(self.kinds)

    # ------------------------------------------------------------------ what it says
    @property
    def d(self) -> int:
        """Number of axes."""
        return len(self.kinds)

    @property
    def periodic(self) -> np.ndarray:
        """Which axes are periodic, shape (d,), bool: the minimum image applies there only."""
        return np.array([kind == PERIODIC for kind in self.kinds])

    @property
    def wall_axes(self) -> tuple[int, ...]:
        """Axes with two flat walls."""
        return tuple(axis for axis, kind in enumerate(self.kinds) if kind == WALLS)

    @property
    def cylinder_axes(self) -> tuple[int, ...]:
        """The two axes of the cylinder's circle, or ()."""
        return tuple(axis for axis, kind in enumerate(self.kinds) if kind == CYLINDER)

    @property
    def is_periodic(self) -> bool:
        """Periodic along every axis."""
        return all(kind == PERIODIC for kind in self.kinds)

    @property
    def n_periodic(self) -> int:
        """Number of periodic axes: the translations a packing keeps as zero modes."""
        return self.kinds.count(PERIODIC)

    @property
    def zero_modes(self) -> int:
        """Rigid motions that leave the container unchanged: the translations along the
        periodic axes, plus the rotation about a cylinder's axis."""
        return self.n_periodic + (1 if self.cylinder_axes else 0)

    def check_block_matrix(self, matrix: np.ndarray) -> None:
        """Raise ValueError (one line) unless the box `matrix` (shape (d, d), box vectors as
        columns) keeps every bounded axis apart: its off-diagonal entries in the rows and
        columns of the walls' and the cylinder's axes are zero, so that a shear of the
        periodic axes never tilts a wall."""
        bounded = ~self.periodic
        off = ~np.eye(self.d, dtype=bool) & (bounded[:, None] | bounded[None, :])
        if np.any(matrix[off] != 0.0):
            raise ValueError(f"a sheared box in a container ({self.describe()}) may shear its "
                             f"periodic axes only: the walls' axes must stay orthogonal")

    def search_cell(self, matrix: np.ndarray) -> np.ndarray:
        """The box `matrix` (shape (d, d), columns the box vectors, bounded axes apart) with
        every bounded axis's vector stretched by `BOUNDED_PADDING`: the lattice whose
        minimum image, wrap and pair search (`calippso.geometry.periodic`,
        `calippso.geometry.sheared_search`) act along the periodic axes alone."""
        padded = np.array(matrix, dtype=np.float64)
        padded[:, ~self.periodic] *= BOUNDED_PADDING
        return padded

    def box_cell(self, cell: np.ndarray) -> np.ndarray:
        """The box matrix of a `search_cell` (its inverse), shape (d, d)."""
        matrix = np.array(cell, dtype=np.float64)
        matrix[:, ~self.periodic] /= BOUNDED_PADDING
        return matrix

    def describe(self) -> str:
        """For messages and reports, e.g. "walls in x, y; periodic in z"."""
        if self.is_periodic:
            return "periodic"
        parts = []
        for kind, label in ((WALLS, "walls in"), (CYLINDER, "cylinder in"),
                            (PERIODIC, "periodic in")):
            axes = [axis_name(axis) for axis, k in enumerate(self.kinds) if k == kind]
            if axes:
                parts.append(f"{label} {', '.join(axes)}")
        return "; ".join(parts)

    def volume(self, box: np.ndarray) -> float:
        """Volume of the container, in length^d: Π L_μ, with the cylinder's square replaced
        by its inscribed circle (π L²/4)."""
        box = np.asarray(box, dtype=float)
        volume = float(np.prod(box))
        if self.cylinder_axes:
            volume *= pi / 4
        return volume

    # ------------------------------------------------------------------ checks
    def check(self, positions: np.ndarray, diameters: np.ndarray, box: np.ndarray) -> None:
        """Raise ValueError (one line) unless every particle lies inside the container.

        A particle is inside when its distance to every wall is at least its radius, up to
        `INSIDE_TOLERANCE` × its diameter.

        Parameters
        ----------
        positions : ndarray, shape (N, d)
            Centres (length units).
        diameters : ndarray, shape (N,)
        box : ndarray, shape (d,)
        """
        if self.d != box.shape[0]:
            raise ValueError(f"boundaries have {self.d} axes but the box has {box.shape[0]}")
        radius = 0.5 * diameters
        slack = INSIDE_TOLERANCE * diameters
        for axis in self.wall_axes:
            if diameters.max() > box[axis]:
                raise ValueError(f"container smaller than a particle: the walls in "
                                 f"{axis_name(axis)} are {box[axis]:g} apart, the largest "
                                 f"diameter is {diameters.max():g}")
            x = positions[:, axis]
            clearance = np.minimum(x, box[axis] - x) - radius
            self._refuse_outside(clearance, slack, f"the walls in {axis_name(axis)} at 0 and "
                                 f"{box[axis]:g}")
        if self.cylinder_axes:
            a, b = self.cylinder_axes
            if not np.isclose(box[a], box[b], rtol=1e-12, atol=0.0):
                raise ValueError(f"a cylinder needs equal box sides in {axis_name(a)} and "
                                 f"{axis_name(b)}, got {box[a]:g} and {box[b]:g}")
            if diameters.max() > box[a]:
                raise ValueError(f"container smaller than a particle: the cylinder's diameter "
                                 f"is {box[a]:g}, the largest particle diameter "
                                 f"{diameters.max():g}")
            offset = positions[:, [a, b]] - 0.5 * box[[a, b]]
            clearance = 0.5 * box[a] - np.sqrt(np.einsum("nk,nk->n", offset, offset)) - radius
            self._refuse_outside(clearance, slack, f"the cylinder of diameter {box[a]:g} in "
                                 f"{axis_name(a)}, {axis_name(b)}")

    @staticmethod
    def _refuse_outside(clearance: np.ndarray, slack: np.ndarray, container: str) -> None:
        outside = clearance < -slack
        if outside.any():
            k = int(np.argmin(clearance / slack))
            raise ValueError(f"{int(outside.sum())} particle(s) outside the container or "
                             f"overlapping its wall ({container}); the worst, particle {k}, "
                             f"crosses it by {-clearance[k]:.3e}")
