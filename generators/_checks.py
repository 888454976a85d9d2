"""Input validation shared by the generators: one place, errors that name the bad argument."""

from __future__ import annotations

import numpy as np

__all__ = ["check_diameters", "check_dimension", "check_positive", "check_phi", "phi_estimate",
           "check_boundaries", "wall_gaps", "remove_roundoff_overlap"]


def check_diameters(diameters) -> np.ndarray:
    """Diameters as a float64 (N,) array; ValueError on a wrong shape, NaN/inf or a value ≤ 0."""
    try:
        array = np.array(diameters, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"diameters must be numeric: {error}") from None
    if array.ndim != 1 or array.shape[0] == 0:
        raise ValueError(f"diameters must be a non-empty 1-d array, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError("diameters contain NaN or inf")
    if np.any(array <= 0):
        raise ValueError(
            f"diameters must be > 0; {int(np.count_nonzero(array <= 0))} are non-positive "
            f"(smallest {array.min():g})"
        )
    return array


def check_dimension(d) -> int:
    """The dimension as an int ≥ 2; ValueError otherwise."""
    if d is None or int(d) != d or d < 2:
        raise ValueError(f"dimension d must be an integer >= 2, got d = {d!r}")
    return int(d)


def check_positive(value, name: str, allow_zero: bool = False) -> float:
    """A finite float > 0 (or ≥ 0); ValueError naming `name` otherwise."""
    value = float(value)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite number {bound}, got {value!r}")
    return value


def check_phi(phi, name: str = "phi") -> float:
    """A packing fraction in (0, 1); ValueError naming `name` otherwise."""
    phi = float(phi)
    if not (0.0 < phi < 1.0):
        raise ValueError(f"{name} must lie in (0, 1), got {phi!r} (impossible packing fraction)")
    return phi


def phi_estimate(d: int) -> float:
    """Typical random jamming density in dimension d (a default for nominal densities).

    d = 2: 0.84 (bidisperse discs); d ≥ 3: the fit φ ≈ (2.56 d − 2.72)/2^d of Skoge et al.
    (0.62, 0.47, 0.32 at d = 3, 4, 5).
    """
    if d == 2:
        return 0.84
    return (2.56 * d - 2.72) / 2.0**d


def check_boundaries(boundaries, d: int, generator: str, kinds: tuple[str, ...]):
    """The boundaries of a run: all periodic when None, else `boundaries` if every one of
    its axes is of one of `kinds`; ValueError (one line naming `generator`) otherwise.

    Parameters
    ----------
    boundaries : calippso.Boundaries or None
    d : int
        Dimension of the run.
    generator : str
        Name of the generator, for the message.
    kinds : tuple of str
        The boundary kinds the generator handles (`calippso.geometry.boundaries.KINDS`).
    """
    from calippso.geometry.boundaries import Boundaries

    if boundaries is None:
        return Boundaries.all_periodic(d)
    if not isinstance(boundaries, Boundaries):
        raise ValueError(f"boundaries must be a calippso.Boundaries, got "
                         f"{type(boundaries).__name__}")
    if boundaries.d != d:
        raise ValueError(f"boundaries have {boundaries.d} axes, expected d = {d}")
    unsupported = sorted(set(boundaries.kinds) - set(kinds))
    if unsupported and kinds == ("periodic",):
        raise ValueError(f"{generator} makes periodic packings only, got "
                         f"{boundaries.describe()}")
    if unsupported:
        raise ValueError(f"{generator} does not handle {', '.join(unsupported)} boundaries "
                         f"({boundaries.describe()}); it takes {', '.join(kinds)}")
    return boundaries


def wall_gaps(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
              periodic: np.ndarray, cylinder: tuple[int, ...] = ()
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Relative gap of every particle to each wall: h = δ/(σ_i/2) − 1, δ the centre's
    distance to the wall (the wall as a partner at contact distance σ_i/2, as in
    `calippso.geometry.walls`; a shrink of all diameters by c turns h into (1 + h)/c − 1, as for a
    pair). For a cylinder δ = L/2 − ρ, ρ the centre's distance from its axis.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (length units).
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    periodic : ndarray, shape (d,), bool
        Periodic axes; the others have walls at 0 (wall 2μ) and L_μ (wall 2μ + 1), except
        the cylinder's.
    cylinder : tuple of int
        The two axes (a, b) of a cylinder (wall 2d, `calippso.geometry.walls.cylinder_wall`), or ().

    Returns
    -------
    particle, wall : ndarray of int64, shape (N (2 W + C),)
        Every particle against each of the 2 W flat walls (W walled axes), then the
        cylinder (C = 1 with one, else 0), particle-major.
    gaps : ndarray, shape (N (2 W + C),)
    """
    n, d = positions.shape
    flat = ~np.asarray(periodic, dtype=bool)
    flat[list(cylinder)] = False
    axes = np.flatnonzero(flat)
    distances = np.stack([positions[:, axes], box[axes] - positions[:, axes]], axis=2)
    walls = (2 * axes[:, None] + np.arange(2)[None, :]).reshape(-1)
    gaps = (2.0 * distances / diameters[:, None, None] - 1.0).reshape(n, -1)
    if cylinder:
        half = 0.5 * box[cylinder[0]]
        offset = positions[:, list(cylinder)] - half
        rho = np.sqrt(np.einsum("nk,nk->n", offset, offset))
        gaps = np.concatenate([gaps, (2.0 * (half - rho) / diameters - 1.0)[:, None]], axis=1)
        walls = np.append(walls, 2 * d)
    particle = np.repeat(np.arange(n, dtype=np.int64), walls.size)
    return particle, np.tile(walls.astype(np.int64), n), gaps.reshape(-1)


#: Relative gap `remove_roundoff_overlap` leaves on the closest pair (a few units of round-off).
ROUNDOFF_MARGIN = 1e-15


def remove_roundoff_overlap(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                            periodic: np.ndarray | None = None,
                            cylinder: tuple[int, ...] = ()) -> tuple[np.ndarray, float]:
    """Scale all diameters down by the (tiny) relative overlap left by round-off, if any,
    between two particles or a particle and a wall (flat or the cylinder's).

    The check is an independent periodic KD-tree search (`calippso.geometry.neighbors.min_gap`). The
    factor is 1 − (−h + `ROUNDOFF_MARGIN`), not `calippso.geometry.neighbors.shrink_to_margin`'s
    (1 + h)(1 − margin), because the two differ in the last bit for some gaps h and the
    generators' outputs must stay the same bit for bit.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (length units).
    diameters : ndarray, shape (N,)
        Diameters (length units).
    box : ndarray, shape (d,)
        Box sides (length units).
    periodic : ndarray, shape (d,), bool, optional
        Periodic axes; flat walls at 0 and L_μ along the others (`wall_gaps`). None: every
        axis periodic.
    cylinder : tuple of int
        The two axes of a cylinder (among the non-periodic ones), or ().

    Returns
    -------
    diameters : ndarray, shape (N,)
        The diameters, possibly multiplied by (1 − correction).
    correction : float
        Relative shrink applied (0.0 if no pair overlapped).
    """
    from calippso.geometry.neighbors import min_gap

    gap, _ = min_gap(positions, diameters, box, periodic)
    if periodic is not None and not np.all(periodic):
        gap = min(gap, float(wall_gaps(positions, diameters, box, periodic,
                                       cylinder)[2].min()))
    if gap >= 0:
        return diameters, 0.0
    correction = -gap + ROUNDOFF_MARGIN
    return diameters * (1.0 - correction), correction
