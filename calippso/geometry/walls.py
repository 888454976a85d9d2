"""Hard container walls in the jamming core: particle–wall rows, their forces, and the loads.

A box with flat walls along axis μ (`calippso.geometry.boundaries`) has a wall at 0 and one at L_μ.
Walls are numbered 2μ (the wall at 0) and 2μ + 1 (the wall at L_μ). A cylinder (a circle of
diameter L inscribed in the box in the plane of its two axes a, b, centred at L/2) is one
wall, numbered 2d (`cylinder_wall`). A particle i of diameter σ_i at distance δ from a wall
touches it when δ = σ_i/2: the wall plays the part of a partner particle with contact
distance σ_w = σ_i/2 that never moves. Its inward normal e_w (+e_μ at 0, −e_μ at L_μ; −ρ̂ for
the cylinder, with ρ the particle's offset from the cylinder's axis) is the direction of the
wall's force on the particle.

The LP row of a particle–wall pair has the form of a pair row (`calippso.lp`),
e_w·s_i − γ σ_w²/(2δ') ≥ −(δ' − σ_w)(δ' + σ_w)/(2δ'), which is δ'² + 2δ' e_w·s_i ≥ Γ σ_w²
divided by 2δ': its dual μ_w is twice the wall's force on the particle, in the same units as
the pair forces. For a flat wall δ' = δ and the row is safe: δ + e_w·s_i ≥ (δ² + Γσ_w²)/(2δ) ≥
√Γ σ_w. A curved wall moves away from the tangent plane: over a step with components at
most b, the distance to the cylinder is at least δ + e_w·s − |s_⊥|²/(2ρ) ≥ δ' + e_w·s with
δ' = δ − b²/ρ (`WallRows.row_distances`; docs/theory.md), and the row with δ' is safe.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

#: Halvings of a move out of a layer before the particle is left in place.
REACH_HALVINGS = 30
#: Axes in the plane of a cylinder's circle: a step with components at most b moves a
#: particle by at most √CIRCLE_AXES · b in that plane.
CIRCLE_AXES = 2

__all__ = ["WallRows", "wall_rows_within", "wall_rows_of", "wall_net_forces",
           "wall_equilibrium_columns", "wall_loads", "cylinder_load", "cylinder_wall",
           "wall_ids", "EMPTY_WALLS"]


def cylinder_wall(d: int) -> int:
    """The number of a cylinder's wall in dimension d: 2d, after the flat walls."""
    return 2 * d


def wall_ids(d: int) -> int:
    """How many wall numbers dimension d uses (2d flat walls and a cylinder): the factor of
    the keys particle · wall_ids + wall (`WallRows.keys`)."""
    return 2 * d + 1


@dataclass(frozen=True)
class WallRows:
    """Particle–wall pairs with their geometry.

    Attributes
    ----------
    particle : ndarray, shape (K,), int64
        The particles.
    wall : ndarray, shape (K,), int64
        Their walls: 2μ + side for a flat wall (side 0 at 0, side 1 at L_μ), 2d for the
        cylinder.
    distances : ndarray, shape (K,)
        Centre-to-wall distances δ (length units).
    sigma : ndarray, shape (K,)
        Contact distances σ_w = σ_i/2.
    normals : ndarray, shape (K, d)
        Inward unit normals e_w at the particle: the direction of the wall's force on it.
    curvature : ndarray, shape (K,)
        1/ρ for a cylinder row (ρ: the centre's distance from the cylinder's axis), 0 for a
        flat wall (1/length units).
    """

    particle: np.ndarray
    wall: np.ndarray
    distances: np.ndarray
    sigma: np.ndarray
    normals: np.ndarray
    curvature: np.ndarray

    def __len__(self) -> int:
        return int(self.particle.shape[0])

    @property
    def vectors(self) -> np.ndarray:
        """δ e_w, shape (K, d): the row in the form of a pair's separation r (|r| = δ, and
        the gradient of δ² on the particle is 2 r)."""
        return self.distances[:, None] * self.normals

    @property
    def gaps(self) -> np.ndarray:
        """Relative gaps δ/σ_w − 1 (negative when a particle crosses its wall), shape (K,)."""
        return self.distances / self.sigma - 1.0

    def smallest_gap(self) -> float:
        """The smallest relative gap, +inf when there is no row."""
        return float(self.gaps.min()) if len(self) else float("inf")

    def keys(self, n_walls: int) -> np.ndarray:
        """One integer per row, particle · n_walls + wall, shape (K,) (`wall_ids`)."""
        return self.particle * n_walls + self.wall

    def row_distances(self, step_bound: float) -> np.ndarray:
        """The distances δ' of the LP rows for steps with components at most `step_bound`:
        δ for a flat wall, δ − b²/ρ for the cylinder (its curvature), shape (K,)."""
        return self.distances - 0.5 * CIRCLE_AXES * step_bound**2 * self.curvature

    def subset(self, mask: np.ndarray) -> "WallRows":
        """The rows selected by a boolean mask or an index array."""
        return WallRows(self.particle[mask], self.wall[mask], self.distances[mask],
                        self.sigma[mask], self.normals[mask], self.curvature[mask])

    @staticmethod
    def concatenate(parts: list["WallRows"], d: int) -> "WallRows":
        """The rows of several sets, in order (dimension d when `parts` is empty)."""
        if not parts:
            return empty_walls(d)
        return WallRows(*(np.concatenate([getattr(part, name) for part in parts])
                          for name in ("particle", "wall", "distances", "sigma", "normals",
                                       "curvature")))


def empty_walls(d: int) -> WallRows:
    """No particle–wall pair, in dimension d."""
    return WallRows(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0),
                    np.zeros((0, d)), np.zeros(0))


#: No particle–wall pair (dimension-free: for `len` and `keys` only).
EMPTY_WALLS = empty_walls(0)


def wall_rows_of(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                 particle: np.ndarray, wall: np.ndarray,
                 cylinder_axes: tuple[int, ...] = ()) -> WallRows:
    """Geometry of given particle–wall pairs (index arrays of equal length, shape (K,)).

    Parameters
    ----------
    positions : ndarray, shape (N, d)
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    particle, wall : ndarray, shape (K,), int
        The pairs (`WallRows` numbering).
    cylinder_axes : tuple of int
        The cylinder's two axes (`calippso.geometry.boundaries.Boundaries.cylinder_axes`), needed
        when a pair is with the cylinder.
    """
    particle = np.asarray(particle, dtype=np.int64)
    wall = np.asarray(wall, dtype=np.int64)
    k, d = particle.shape[0], positions.shape[1]
    distances, normals, curvature = np.zeros(k), np.zeros((k, d)), np.zeros(k)
    flat = wall < cylinder_wall(d)
    axis = wall[flat] // 2
    x = positions[particle[flat], axis]
    at_zero = wall[flat] % 2 == 0
    distances[flat] = np.where(at_zero, x, box[axis] - x)
    normals[np.flatnonzero(flat), axis] = np.where(at_zero, 1.0, -1.0)
    on_cylinder = ~flat
    if on_cylinder.any():
        if len(cylinder_axes) != 2:
            raise ValueError("a contact with a cylinder in a box without one")
        plane = list(cylinder_axes)
        offset = positions[particle[on_cylinder]][:, plane] - 0.5 * box[plane]
        rho = np.sqrt(np.einsum("kc,kc->k", offset, offset))
        # on the axis itself any direction is the normal (and the wall is far away)
        safe_rho = np.where(rho > 0, rho, 1.0)
        outward = np.where(rho[:, None] > 0, offset / safe_rho[:, None], [1.0, 0.0])
        rows = np.flatnonzero(on_cylinder)
        distances[rows] = 0.5 * box[plane[0]] - rho
        normals[rows[:, None], plane] = -outward
        curvature[rows] = np.where(rho > 0, 1.0 / safe_rho, np.inf)
    return WallRows(particle, wall, distances, 0.5 * diameters[particle], normals, curvature)


def wall_rows_within(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                     boundaries, reach: float, growth: float = 1.0) -> WallRows:
    """Every particle–wall pair with δ ≤ growth · σ_i/2 + (how far a step of bound `reach`
    moves the particle towards the wall).

    Parameters
    ----------
    positions : ndarray, shape (N, d)
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    boundaries : calippso.geometry.boundaries.Boundaries
        The container: its flat walls and its cylinder.
    reach : float
        Bound b on each displacement component (length units, ≥ 0): the step bound when
        choosing LP rows. A flat wall comes at most b closer, the cylinder √2 b.
    growth : float
        Factor on the contact distance σ_i/2: a bound on √Γ when choosing LP rows.

    Returns
    -------
    WallRows
        Sorted by (wall, particle).
    """
    n, d = positions.shape
    every = np.arange(n, dtype=np.int64)
    parts = []
    for axis in boundaries.wall_axes:
        for side in (0, 1):
            rows = wall_rows_of(positions, diameters, box, every,
                                np.full(n, 2 * axis + side, dtype=np.int64))
            parts.append(rows.subset(rows.distances <= growth * rows.sigma + reach))
    if boundaries.cylinder_axes:
        rows = wall_rows_of(positions, diameters, box, every,
                            np.full(n, cylinder_wall(d), dtype=np.int64),
                            boundaries.cylinder_axes)
        parts.append(rows.subset(rows.distances
                                 <= growth * rows.sigma + np.sqrt(CIRCLE_AXES) * reach))
    return WallRows.concatenate(parts, d)


def wall_net_forces(n: int, particle: np.ndarray, normals: np.ndarray,
                    forces: np.ndarray) -> np.ndarray:
    """Net force of the walls on every particle, shape (N, d): f e_w per contact.

    Parameters
    ----------
    n : int
    particle : ndarray, shape (K,), int
    normals : ndarray, shape (K, d)
        Inward normals e_w (`WallRows.normals`).
    forces : ndarray, shape (K,)
    """
    total = np.zeros((n, normals.shape[1]))
    np.add.at(total, particle, forces[:, None] * normals)
    return total


def wall_equilibrium_columns(n: int, particle: np.ndarray, normals: np.ndarray):
    """The (n·d, K) sparse columns of the equilibrium matrix for K wall contacts: column k
    holds e_w in the rows of its particle (`calippso.geometry.contacts.equilibrium_matrix`)."""
    d = normals.shape[1]
    k = particle.shape[0]
    rows = (particle[:, None] * d + np.arange(d)).ravel()
    columns = np.repeat(np.arange(k), d)
    values = normals.ravel()
    keep = values != 0
    return sp.csr_matrix((values[keep], (rows[keep], columns[keep])), shape=(n * d, k))


def wall_loads(d: int, wall: np.ndarray, forces: np.ndarray) -> np.ndarray:
    """The force the particles exert on every flat wall, along its axis, shape (d, 2).

    Entry (μ, 0) is the μ-component of the total force on the wall at 0 (≤ 0: pushed out of
    the box), (μ, 1) that on the wall at L_μ (≥ 0); a row of zeros for an axis without walls
    or without wall contacts. In balance, the two entries of a row sum to zero. Contacts
    with a cylinder are not counted (`cylinder_load`).
    """
    flat = wall < cylinder_wall(d)
    loads = np.zeros(2 * d)
    sign = 1.0 - 2.0 * (wall[flat] % 2)
    np.add.at(loads, wall[flat], -sign * forces[flat])
    return loads.reshape(d, 2)


def cylinder_load(d: int, wall: np.ndarray, forces: np.ndarray) -> float:
    """The total outward force of the particles on a cylinder: the sum of the magnitudes of
    its contact forces (it has no net force, by symmetry of balance)."""
    return float(forces[wall == cylinder_wall(d)].sum())


def out_of_layer_moves(search, wall_axes: tuple[int, ...], wall_particles: np.ndarray,
                       step: float, touching: float, coplanar: float) -> np.ndarray | None:
    """Positions with every particle held only within a layer parallel to a wall moved out
    of that layer, as far as `step` allows without any overlap; None if none can move.

    Equal spheres at a flat wall form layers whose centres lie in one plane. A particle with
    no wall contact whose touching pairs (relative gap below `touching`) all lie in such a
    plane (|n_μ| ≤ `coplanar` along the wall's axis μ) can leave the plane at no first-order
    cost: an LP cannot see that doing so opens its contacts (at second order) and lets Γ
    grow. Each such particle moves along +e_μ or −e_μ, whichever allows more, by at most
    `step` and half its room to the wall it approaches; the movers of a pair that would
    overlap (more than it did before) are halved until none does (checked on the moved
    configuration, exactly).

    Parameters
    ----------
    search : calippso.geometry.neighbors.NeighborSearch
        The configuration (mean diameters).
    wall_axes : tuple of int
        Axes with flat walls.
    wall_particles : ndarray, int
        Particles with a wall contact (they stay).
    step : float
        Largest move (mean diameters).
    touching : float
        Pairs below this relative gap touch.
    coplanar : float
        A touching pair with |n_μ| at most this lies in the plane normal to axis μ.
    """
    n, d = search.positions.shape
    close = search.pairs_within(float(search.diameters.max()) * (1.0 + touching))
    touch = close.subset(close.gaps < touching)
    ends = np.concatenate([touch.i, touch.j])
    touches = np.bincount(ends, minlength=n)
    free = (touches > 0)
    free[wall_particles] = False
    axis_of = np.full(n, -1)
    for axis in wall_axes:
        across = np.abs(touch.vectors[:, axis]) / touch.distances > coplanar
        leaves = np.bincount(ends, np.concatenate([across, across]).astype(float),
                             minlength=n) == 0
        axis_of[free & leaves & (axis_of < 0)] = axis
    movers = np.flatnonzero(axis_of >= 0)
    if not movers.size:
        return None
    best = np.zeros(n)
    best_move = np.zeros((n, d))
    for sign in (1.0, -1.0):
        move = np.zeros((n, d))
        move[movers, axis_of[movers]] = sign
        reach = _reach(search, move, movers, axis_of, step)
        better = reach > best
        best[better], best_move[better] = reach[better], move[better]
    if not np.any(best > 0):
        return None
    return search.positions + best[:, None] * best_move


def _reach(search, move: np.ndarray, movers: np.ndarray, axis_of: np.ndarray,
           step: float) -> np.ndarray:
    """Largest safe move of every particle along its unit `move` (see `out_of_layer_moves`),
    shape (N,); 0 for particles that do not move.

    Every mover starts at `step` (at most half its room to the wall ahead); the moved
    configuration is checked exactly, and the movers of a pair that would overlap (more
    than before) are halved, up to `REACH_HALVINGS` times (then none moves).
    """
    n = move.shape[0]
    reach = np.zeros(n)
    axis = axis_of[movers]
    x = search.positions[movers, axis]
    ahead = np.where(move[movers, axis] > 0, search.box[axis] - x, x)
    room = ahead - 0.5 * search.diameters[movers]
    reach[movers] = np.minimum(step, 0.5 * np.maximum(room, 0.0))
    cutoff = float(search.diameters.max()) + 2.0 * step
    before = search.pairs_within(cutoff)
    floor = dict(zip((before.i * n + before.j).tolist(), np.minimum(before.gaps, 0.0).tolist()))
    for _ in range(REACH_HALVINGS):
        moved = type(search)(search.positions + reach[:, None] * move, search.diameters,
                             search.box, search.periodic)
        after = moved.pairs_within(cutoff)
        keys = (after.i * n + after.j).tolist()
        allowed = np.array([floor.get(key, 0.0) for key in keys])
        bad = after.gaps < allowed
        if not bad.any():
            return reach
        culprits = np.unique(np.concatenate([after.i[bad], after.j[bad]]))
        reach[culprits] *= 0.5
    reach[:] = 0.0
    return reach
