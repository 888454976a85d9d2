"""`SpherocylinderPacking`: hard spherocylinders in a periodic rectangular box (numpy only)."""

from __future__ import annotations

from dataclasses import dataclass
from math import pi

import numpy as np

from calippso.geometry.periodic import wrap

__all__ = ["SpherocylinderPacking", "spherocylinder_volume", "min_particles_for_box"]

#: Axes must have unit norm to this relative tolerance (they are then renormalised exactly).
AXIS_NORM_TOLERANCE = 1e-6


def spherocylinder_volume(diameter, length):
    """Volume of a spherocylinder, π d³/6 + π d² l/4 = π d³/6 · (1.5 γ + 1), γ = l/d.

    Parameters
    ----------
    diameter : float or ndarray
        Diameter(s) d (length units).
    length : float or ndarray
        Cylinder length(s) l ≥ 0 (length units), same shape as `diameter`.

    Returns
    -------
    float or ndarray
        Volume(s) in length³.
    """
    diameter = np.asarray(diameter, dtype=np.float64)
    return pi * diameter**3 / 6.0 + pi * diameter**2 * np.asarray(length, dtype=np.float64) / 4.0


def min_particles_for_box(aspect_ratio: float, density: float) -> int:
    """Smallest N for which a monodisperse packing of aspect ratio γ at density η fits the box.

    A particle (tip to tip l + d = (γ + 1) d) must stay shorter than half the cubic box side L,
    with L³ = N π d³ (1.5 γ + 1) / (6 η). Hence N > 48 (γ + 1)³ η / (π (1.5 γ + 1)).

    Parameters
    ----------
    aspect_ratio : float
        γ = l / d ≥ 0.
    density : float
        Packing fraction η of the box (the largest the particles will take).

    Returns
    -------
    int
        The smallest admissible N.
    """
    bound = 48.0 * (aspect_ratio + 1.0) ** 3 * density / (pi * (1.5 * aspect_ratio + 1.0))
    return int(np.floor(bound)) + 1


def _array(value, name: str, shape_text: str, ndim: int) -> np.ndarray:
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be numeric, got {type(value).__name__}: {error}") from None
    if array.ndim != ndim:
        raise ValueError(f"{name} must have shape {shape_text}, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = int(np.count_nonzero(~np.isfinite(array)))
        raise ValueError(f"{name} contains {bad} non-finite value(s) (NaN or inf)")
    return array


@dataclass(frozen=True, eq=False)
class SpherocylinderPacking:
    """Hard spherocylinders in a periodic, rectangular 3-d box.

    Particle i is the set of points within d_i / 2 of its shaft, the segment
    r_i + λ u_i, |λ| ≤ l_i / 2.

    Parameters
    ----------
    positions : array_like, shape (N, 3)
        Centres r_i, in length units (any real values; `wrapped()` maps them into the box).
    axes : array_like, shape (N, 3)
        Unit axes u_i (norms must be 1 to 1e-6; they are renormalised). u and −u are the same
        orientation.
    diameters : array_like, shape (N,)
        Diameters d_i > 0, in length units.
    lengths : array_like, shape (N,)
        Cylinder lengths l_i ≥ 0 (without the caps; 0 for a sphere), in length units.
    box : array_like, shape (3,) or scalar
        Box sides L_μ > 0 (a scalar means a cubic box).

    Raises
    ------
    ValueError
        On wrong shapes, non-finite values, non-unit axes, non-positive diameters, negative
        lengths, non-positive box sides, or a particle whose tip-to-tip length l + d is not
        below half the smallest box side (the minimum-image convention could then miss
        contacts).

    Notes
    -----
    Overlaps are not checked here; `generators.spherocylinders.geometry.min_distance_ratio`
    checks them with the exact shaft distance.
    """

    positions: np.ndarray
    axes: np.ndarray
    diameters: np.ndarray
    lengths: np.ndarray
    box: np.ndarray

    def __post_init__(self) -> None:
        positions = _array(self.positions, "positions", "(N, 3)", 2)
        axes = _array(self.axes, "axes", "(N, 3)", 2)
        diameters = _array(self.diameters, "diameters", "(N,)", 1)
        lengths = _array(self.lengths, "lengths", "(N,)", 1)
        n = positions.shape[0]
        if n == 0:
            raise ValueError("the packing is empty: positions has no rows")
        if positions.shape[1] != 3:
            raise ValueError(f"spherocylinders are 3-dimensional: positions must have shape "
                             f"(N, 3), got {positions.shape}")
        if axes.shape != positions.shape:
            raise ValueError(f"axes must have shape {positions.shape}, got {axes.shape}")
        for name, array in (("diameters", diameters), ("lengths", lengths)):
            if array.shape[0] != n:
                raise ValueError(f"{name} has {array.shape[0]} entries but positions has "
                                 f"{n} particles")
        norms = np.linalg.norm(axes, axis=1)
        off = np.abs(norms - 1.0) > AXIS_NORM_TOLERANCE
        if np.any(off):
            worst = int(np.argmax(np.abs(norms - 1.0)))
            raise ValueError(f"axes must be unit vectors: {int(off.sum())} have |u| - 1 beyond "
                             f"{AXIS_NORM_TOLERANCE:g} (particle {worst}: |u| = {norms[worst]:g})")
        axes = axes / norms[:, None]
        if np.any(diameters <= 0):
            raise ValueError(f"diameters must be > 0; found {int(np.count_nonzero(diameters <= 0))}"
                             f" non-positive (smallest {diameters.min():g})")
        if np.any(lengths < 0):
            raise ValueError(f"lengths must be >= 0; found {int(np.count_nonzero(lengths < 0))} "
                             f"negative (smallest {lengths.min():g})")
        box_input = [self.box] * 3 if np.ndim(self.box) == 0 else self.box
        box = _array(box_input, "box", "(3,)", 1)
        if box.shape[0] != 3:
            raise ValueError(f"box must have 3 sides, got {box.shape[0]}")
        if np.any(box <= 0):
            raise ValueError(f"box sides must be > 0, got {box.tolist()}")
        longest = float(np.max(lengths + diameters))
        if longest >= 0.5 * box.min():
            raise ValueError(f"box too small: the longest particle (l + d = {longest:g}) is not "
                             f"below half the smallest box side {box.min():g}; periodic images "
                             f"would interact")
        for name, array in (("positions", positions), ("axes", axes), ("diameters", diameters),
                            ("lengths", lengths), ("box", box)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @property
    def n(self) -> int:
        """Number of particles N."""
        return self.positions.shape[0]

    @property
    def d(self) -> int:
        """Dimension (always 3)."""
        return 3

    @property
    def volume(self) -> float:
        """Box volume Π L_μ, in length³."""
        return float(np.prod(self.box))

    @property
    def aspect_ratios(self) -> np.ndarray:
        """γ_i = l_i / d_i, shape (N,)."""
        return self.lengths / self.diameters

    @property
    def particle_volumes(self) -> np.ndarray:
        """π d³/6 · (1.5 γ + 1) per particle, shape (N,), in length³."""
        return spherocylinder_volume(self.diameters, self.lengths)

    @property
    def phi(self) -> float:
        """Packing fraction φ = Σ_i π d_i³/6 · (1.5 γ_i + 1) / Π L_μ (overlaps counted twice)."""
        return float(np.sum(self.particle_volumes) / self.volume)

    @property
    def mean_diameter(self) -> float:
        """Mean diameter, in length units."""
        return float(self.diameters.mean())

    def order_tensor(self) -> np.ndarray:
        """Q = (1/N) Σ_i (3/2 u_i u_iᵀ − 1/2 I), shape (3, 3), symmetric and traceless."""
        return 1.5 * (self.axes.T @ self.axes) / self.n - 0.5 * np.eye(3)

    def nematic_order(self) -> float:
        """Nematic order parameter S: the largest eigenvalue of Q (0 isotropic, 1 aligned).

        For N random isotropic axes S is positive, of order 1/√N (not 0).
        """
        return float(np.linalg.eigvalsh(self.order_tensor())[-1])

    def director(self) -> np.ndarray:
        """Nematic director: the unit eigenvector of Q for S, shape (3,)."""
        return np.linalg.eigh(self.order_tensor())[1][:, -1]

    def wrapped(self) -> "SpherocylinderPacking":
        """The same packing with every centre inside [0, L)."""
        return SpherocylinderPacking(wrap(self.positions, self.box), self.axes, self.diameters, self.lengths, self.box)

    def scaled(self, factor: float) -> "SpherocylinderPacking":
        """The same centres and axes with all diameters and lengths multiplied by `factor`."""
        if not factor > 0:
            raise ValueError(f"factor must be > 0, got {factor}")
        return SpherocylinderPacking(self.positions, self.axes, self.diameters * factor,
                                     self.lengths * factor, self.box)

    def __repr__(self) -> str:
        gammas = np.unique(np.round(self.aspect_ratios, 12))
        kind = f"aspect ratio {gammas[0]:g}" if gammas.size == 1 else \
            f"{gammas.size} aspect ratios {gammas.min():g}…{gammas.max():g}"
        return (f"SpherocylinderPacking(n={self.n}, phi={self.phi:.6f}, {kind}, "
                f"S={self.nematic_order():.4f}, box={self.box.tolist()})")
