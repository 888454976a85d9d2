"""The `Packing` type: hard (hyper)spheres in a box (periodic, or closed by walls: its
`calippso.geometry.boundaries.Boundaries`), its packing fraction and the d-ball volume.

This module imports numpy only, so that every part of the project (the LP core, the Numba
generators, the readers) can share it without pulling in anything heavy. The periodic
geometry lives in `calippso.geometry.periodic`; `minimum_image` and `wrap` are imported here too, for
the modules that take them from this one.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import gamma, pi

import numpy as np

from .boundaries import Boundaries
from .periodic import (lattice_minimum_image, lattice_wrap, minimum_image,
                       shortest_lattice_vector, triangular_box, wrap)

__all__ = ["Packing", "Boundaries", "ball_volume", "minimum_image", "wrap", "packing_of",
           "packing_arrays"]


#: `Packing.sheared` sets a tilt below this fraction of the largest box side to zero (the
#: round-off of rotating the box matrix into upper-triangular form).
SHEAR_ROUNDOFF = 1e-14


def ball_volume(d: int, radius: np.ndarray | float) -> np.ndarray | float:
    """Volume of a d-dimensional ball, V_d(r) = π^{d/2} r^d / Γ(d/2 + 1).

    Parameters
    ----------
    d : int
        Dimension (≥ 1).
    radius : float or ndarray
        Radius or radii, in length units.

    Returns
    -------
    float or ndarray
        Volume(s) in length^d, same shape as `radius`.
    """
    return pi ** (d / 2) * np.asarray(radius, dtype=float) ** d / gamma(d / 2 + 1)


def _as_float_array(value, name: str, ndim: int) -> np.ndarray:
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be numeric, got {type(value).__name__}: {error}") from None
    if array.ndim != ndim:
        expected = "(N, d)" if ndim == 2 else "a 1-d array"
        raise ValueError(f"{name} must have shape {expected}, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = int(np.count_nonzero(~np.isfinite(array)))
        raise ValueError(f"{name} contains {bad} non-finite value(s) (NaN or inf)")
    return array


@dataclass(frozen=True, eq=False)
class Packing:
    """Hard (hyper)spheres in a rectangular box, periodic or closed by walls, or in a
    sheared periodic box.

    Parameters
    ----------
    positions : array_like, shape (N, d)
        Particle centres, in length units. Along periodic axes any real values (`wrapped()`
        maps them into the box); along a bounded axis in [0, L_μ], each particle inside the
        container.
    diameters : array_like, shape (N,)
        Particle diameters σ_i > 0, in length units.
    box : array_like, shape (d,) or scalar
        Box side lengths L_μ > 0 (a scalar means a cubic box).
    boundaries : Boundaries, optional
        How each axis is closed (`calippso.geometry.boundaries`); default: periodic along every axis.
    box_matrix : array_like, shape (d, d), optional
        A sheared periodic box: the box vectors as columns, upper triangular with the
        diagonal equal to `box` (`Packing.sheared` builds it from any box matrix). None (the
        default) is the rectangular box diag(`box`); a diagonal matrix is stored as None.

    Raises
    ------
    ValueError
        On wrong shapes, non-finite values, non-positive diameters or box sides, d < 2, an
        empty packing, a particle wider than half the smallest periodic box side (the
        minimum-image convention could then miss contacts), boundaries of another dimension,
        or a particle outside its container (`Boundaries.check`); a box matrix that is not
        upper triangular with `box` on its diagonal, or one with walls.

    Notes
    -----
    Overlaps are not checked here (a Poisson start overlaps on purpose); `calippso.jam` and the
    generators check them where it matters.
    """

    positions: np.ndarray
    diameters: np.ndarray
    box: np.ndarray
    boundaries: Boundaries | None = None
    box_matrix: np.ndarray | None = None

    def __post_init__(self) -> None:
        positions = _as_float_array(self.positions, "positions", 2)
        diameters = _as_float_array(self.diameters, "diameters", 1)
        n, d = positions.shape
        if n == 0:
            raise ValueError("the packing is empty: positions has no rows")
        if d < 2:
            raise ValueError(f"dimension d must be at least 2, got d = {d}")
        if diameters.shape[0] != n:
            raise ValueError(
                f"diameters has {diameters.shape[0]} entries but positions has {n} particles"
            )
        if np.any(diameters <= 0):
            raise ValueError(
                f"diameters must be > 0; found {int(np.count_nonzero(diameters <= 0))} "
                f"non-positive (smallest {diameters.min():g})"
            )
        box_input = [self.box] * d if np.ndim(self.box) == 0 else self.box
        box = _as_float_array(box_input, "box", 1)
        if box.shape[0] != d:
            raise ValueError(f"box has {box.shape[0]} sides but positions are {d}-dimensional")
        if np.any(box <= 0):
            raise ValueError(f"box sides must be > 0, got {box.tolist()}")
        boundaries = (Boundaries.all_periodic(d) if self.boundaries is None
                      else self.boundaries)
        if not isinstance(boundaries, Boundaries):
            raise ValueError(f"boundaries must be a calippso.Boundaries, got "
                             f"{type(boundaries).__name__}")
        if boundaries.d != d:
            raise ValueError(f"boundaries have {boundaries.d} axes but positions are "
                             f"{d}-dimensional")
        box_matrix = self._checked_box_matrix(box, boundaries)
        object.__setattr__(self, "box_matrix", box_matrix)
        periodic_box = box[boundaries.periodic]
        if box_matrix is not None:
            shortest = shortest_lattice_vector(boundaries.search_cell(box_matrix))
            if diameters.max() >= 0.5 * shortest:
                raise ValueError(
                    f"box too small: the largest diameter {diameters.max():g} is not below "
                    f"half the shortest box vector {shortest:g} of the sheared box; the "
                    f"periodic images would interact")
        elif periodic_box.size and diameters.max() >= 0.5 * periodic_box.min():
            raise ValueError(
                f"box too small: the largest diameter {diameters.max():g} is not below half the "
                f"smallest box side {periodic_box.min():g} of a periodic axis; the periodic "
                f"images would interact"
            )
        if not boundaries.is_periodic:
            boundaries.check(positions, diameters, box)
        object.__setattr__(self, "boundaries", boundaries)
        for name, array in (("positions", positions), ("diameters", diameters), ("box", box)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def _checked_box_matrix(self, box: np.ndarray, boundaries: Boundaries) -> np.ndarray | None:
        """The box matrix as a read-only array, or None for a rectangular box."""
        if self.box_matrix is None:
            return None
        d = box.shape[0]
        matrix = _as_float_array(self.box_matrix, "box_matrix", 2)
        if matrix.shape != (d, d):
            raise ValueError(f"box_matrix must have shape ({d}, {d}), got {matrix.shape}")
        boundaries.check_block_matrix(matrix)
        if np.any(np.tril(matrix, -1) != 0.0):
            raise ValueError("box_matrix must be upper triangular (box vectors as columns); "
                             "Packing.sheared rotates any box matrix into that form")
        if not np.allclose(np.diag(matrix), box, rtol=1e-12, atol=0.0):
            raise ValueError(f"the diagonal of box_matrix {np.diag(matrix).tolist()} differs "
                             f"from box {box.tolist()}")
        if not np.any(np.triu(matrix, 1)):
            return None
        matrix.setflags(write=False)
        return matrix

    @classmethod
    def sheared(cls, positions, diameters, matrix,
                boundaries: Boundaries | None = None) -> "Packing":
        """A packing in a sheared periodic box given by any box matrix (in a container, one
        whose bounded axes stay apart, `Boundaries.check_block_matrix`).

        Parameters
        ----------
        positions : array_like, shape (N, d)
            Centres in the frame of `matrix` (length units).
        diameters : array_like, shape (N,)
        matrix : array_like, shape (d, d)
            Box vectors as columns, det > 0 (length units).
        boundaries : Boundaries, optional
            The container; None: periodic along every axis. Only its periodic axes rotate.

        Returns
        -------
        Packing
            The same packing rotated so that its box matrix is upper triangular with a
            positive diagonal (`calippso.geometry.periodic.triangular_box`); a rectangular box when
            the box vectors are orthogonal and along the axes.
        """
        matrix = _as_float_array(matrix, "box matrix", 2)
        if matrix.shape[0] != matrix.shape[1] or np.linalg.det(matrix) <= 0:
            raise ValueError(f"the box matrix must be square with det > 0, got shape "
                             f"{matrix.shape}")
        boundaries = Boundaries.all_periodic(matrix.shape[0]) if boundaries is None else boundaries
        boundaries.check_block_matrix(matrix)
        periodic = np.flatnonzero(boundaries.periodic)
        block, block_rotation = triangular_box(matrix[np.ix_(periodic, periodic)])
        triangular, rotation = matrix.copy(), np.eye(matrix.shape[0])
        triangular[np.ix_(periodic, periodic)] = np.triu(block)
        rotation[np.ix_(periodic, periodic)] = block_rotation
        # tilts at the round-off of the rotation are no shear
        roundoff = np.triu(np.abs(triangular) < SHEAR_ROUNDOFF * np.diag(triangular).max(), 1)
        triangular[roundoff] = 0.0
        rotated = np.asarray(positions, dtype=np.float64) @ rotation
        return cls(rotated, diameters, np.diag(triangular).copy(),
                   None if boundaries.is_periodic else boundaries, triangular)

    @property
    def is_sheared(self) -> bool:
        """Whether the box is sheared (`box_matrix` is not None)."""
        return self.box_matrix is not None

    @property
    def lattice(self) -> np.ndarray:
        """The box matrix, box vectors as columns, shape (d, d): diag(`box`) for a
        rectangular box."""
        return np.diag(self.box) if self.box_matrix is None else self.box_matrix

    @property
    def search_cell(self) -> np.ndarray:
        """`lattice` with its bounded axes padded (`Boundaries.search_cell`): the lattice of
        the minimum image and the pair search, shape (d, d)."""
        return self.boundaries.search_cell(self.lattice)

    def minimum_image(self, delta: np.ndarray) -> np.ndarray:
        """The minimum image of separations, shape (..., d), in this box (sheared or not)."""
        if self.box_matrix is not None:
            return lattice_minimum_image(delta, self.search_cell)
        periodic = self.periodic
        return minimum_image(delta, self.box, None if periodic.all() else periodic)

    @property
    def n(self) -> int:
        """Number of particles N."""
        return self.positions.shape[0]

    @property
    def d(self) -> int:
        """Dimension d."""
        return self.positions.shape[1]

    @property
    def periodic(self) -> np.ndarray:
        """Which axes are periodic, shape (d,), bool (`Boundaries.periodic`)."""
        return self.boundaries.periodic

    @property
    def volume(self) -> float:
        """Volume of the container, in length^d: the box Π L_μ, or the cylinder inscribed in
        it (`Boundaries.volume`)."""
        return self.boundaries.volume(self.box)

    @property
    def phi(self) -> float:
        """Packing fraction φ = Σ_i V_d(σ_i/2) / the container's volume (overlaps counted
        twice)."""
        return float(np.sum(ball_volume(self.d, self.diameters / 2)) / self.volume)

    @property
    def mean_diameter(self) -> float:
        """Mean diameter, the unit of every tolerance in the project."""
        return float(self.diameters.mean())

    def wrapped(self) -> "Packing":
        """The same packing with every periodic coordinate inside [0, L)."""
        if self.box_matrix is not None:
            return Packing(lattice_wrap(self.positions, self.search_cell), self.diameters,
                           self.box, self.boundaries, self.box_matrix)
        return Packing(wrap(self.positions, self.box, self.periodic), self.diameters, self.box,
                       self.boundaries)

    def scaled_to_phi(self, phi: float) -> "Packing":
        """The same centres with all diameters scaled by one factor to reach packing fraction `phi`."""
        if not phi > 0:
            raise ValueError(f"phi must be > 0, got {phi}")
        factor = (phi / self.phi) ** (1.0 / self.d)
        return Packing(self.positions, self.diameters * factor, self.box, self.boundaries,
                       self.box_matrix)

    def __repr__(self) -> str:
        polydisperse = np.ptp(self.diameters) > 1e-12 * self.diameters.max()
        kind = "polydisperse" if polydisperse else "monodisperse"
        walls = "" if self.boundaries.is_periodic else f", {self.boundaries.describe()}"
        if self.box_matrix is not None:
            walls = f", sheared box_matrix={self.box_matrix.tolist()}"
        return (f"Packing(n={self.n}, d={self.d}, phi={self.phi:.6f}, {kind}, "
                f"box={self.box.tolist()}{walls})")


def packing_of(arrays) -> Packing:
    """The `Packing` held by a mapping of arrays (our `.npz` and HDF5 keys): positions,
    diameters, box, the "boundaries" string when the box has walls, and "box_matrix" when
    it is sheared."""
    boundaries = (Boundaries.from_text(str(np.asarray(arrays["boundaries"])[()]))
                  if "boundaries" in arrays else None)
    box_matrix = arrays["box_matrix"] if "box_matrix" in arrays else None
    return Packing(arrays["positions"], arrays["diameters"], arrays["box"], boundaries,
                   box_matrix)


def packing_arrays(packing: Packing) -> dict[str, np.ndarray]:
    """The arrays of a `Packing` in our `.npz` and HDF5 files: positions, diameters, box,
    "boundaries" (the kind of every axis, e.g. "walls periodic") only when the box is not
    periodic, and "box_matrix" (box vectors as columns) only when it is sheared, so that a
    rectangular periodic file is what it always was."""
    arrays = {"positions": packing.positions, "diameters": packing.diameters,
              "box": packing.box}
    if not packing.boundaries.is_periodic:
        arrays["boundaries"] = np.array(str(packing.boundaries))
    if packing.box_matrix is not None:
        arrays["box_matrix"] = packing.box_matrix
    return arrays
