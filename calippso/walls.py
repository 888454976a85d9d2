"""Flat hard walls in the jamming core: particle–wall rows, their forces, and the loads.

A box with flat walls along axis μ (`calippso.boundaries`) has a wall at 0 and one at L_μ.
Walls are numbered 2μ (the wall at 0) and 2μ + 1 (the wall at L_μ). A particle i of diameter
σ_i at distance δ from a wall touches it when δ = σ_i/2: the wall plays the part of a
partner particle with contact distance σ_w = σ_i/2 whose centre never moves. Its inward
normal e_w (+e_μ at 0, −e_μ at L_μ) is the direction of the wall's force on the particle.

The LP row of a particle–wall pair has the form of a pair row (`calippso.lp`),
e_w·s_i − γ σ_w²/(2δ) ≥ −(δ − σ_w)(δ + σ_w)/(2δ), which is δ² + 2δ e_w·s_i ≥ Γ σ_w² divided by
2δ: its dual μ_w is twice the wall's force on the particle, in the same units as the pair
forces. The row is safe: δ + e_w·s_i ≥ (δ² + Γσ_w²)/(2δ) ≥ √Γ σ_w (docs/theory.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

#: Halvings of a move out of a layer before the particle is left in place.
REACH_HALVINGS = 30

__all__ = ["WallRows", "wall_rows_within", "wall_rows_of", "wall_net_forces",
           "wall_equilibrium_columns", "wall_loads", "EMPTY_WALLS"]


@dataclass(frozen=True)
class WallRows:
    """Particle–wall pairs with their geometry.

    Attributes
    ----------
    particle : ndarray, shape (K,), int64
        The particles.
    wall : ndarray, shape (K,), int64
        Their walls, 2μ + side (side 0 at 0, side 1 at L_μ).
    distances : ndarray, shape (K,)
        Centre-to-wall distances δ (length units).
    sigma : ndarray, shape (K,)
        Contact distances σ_w = σ_i/2.
    """

    particle: np.ndarray
    wall: np.ndarray
    distances: np.ndarray
    sigma: np.ndarray

    def __len__(self) -> int:
        return int(self.particle.shape[0])

    @property
    def axis(self) -> np.ndarray:
        """The axis of every wall, shape (K,)."""
        return self.wall // 2

    @property
    def sign(self) -> np.ndarray:
        """+1 for a wall at 0, −1 for a wall at L: the inward normal along the axis, (K,)."""
        return 1.0 - 2.0 * (self.wall % 2)

    @property
    def gaps(self) -> np.ndarray:
        """Relative gaps δ/σ_w − 1 (negative when a particle crosses its wall), shape (K,)."""
        return self.distances / self.sigma - 1.0

    def smallest_gap(self) -> float:
        """The smallest relative gap, +inf when there is no row."""
        return float(self.gaps.min()) if len(self) else float("inf")

    def keys(self, n_walls: int) -> np.ndarray:
        """One integer per row, particle · n_walls + wall, shape (K,)."""
        return self.particle * n_walls + self.wall

    def subset(self, mask: np.ndarray) -> "WallRows":
        """The rows selected by a boolean mask or an index array."""
        return WallRows(self.particle[mask], self.wall[mask], self.distances[mask],
                        self.sigma[mask])


#: No particle–wall pair.
EMPTY_WALLS = WallRows(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))


def wall_rows_of(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                 particle: np.ndarray, wall: np.ndarray) -> WallRows:
    """Geometry of given particle–wall pairs (index arrays of equal length, shape (K,))."""
    particle = np.asarray(particle, dtype=np.int64)
    wall = np.asarray(wall, dtype=np.int64)
    axis = wall // 2
    x = positions[particle, axis]
    distances = np.where(wall % 2 == 0, x, box[axis] - x)
    return WallRows(particle, wall, distances, 0.5 * diameters[particle])


def wall_rows_within(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                     wall_axes: tuple[int, ...], reach: float, growth: float = 1.0) -> WallRows:
    """Every particle–wall pair with δ ≤ growth · σ_i/2 + reach.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    wall_axes : tuple of int
        Axes with flat walls.
    reach : float
        Extra distance (length units, ≥ 0): the step bound when choosing LP rows.
    growth : float
        Factor on the contact distance σ_i/2: a bound on √Γ when choosing LP rows.

    Returns
    -------
    WallRows
        Sorted by (wall, particle).
    """
    if not wall_axes:
        return EMPTY_WALLS
    n = positions.shape[0]
    every = np.arange(n, dtype=np.int64)
    parts = []
    for axis in wall_axes:
        for side in (0, 1):
            rows = wall_rows_of(positions, diameters, box, every,
                                np.full(n, 2 * axis + side, dtype=np.int64))
            parts.append(rows.subset(rows.distances <= growth * rows.sigma + reach))
    return WallRows(*(np.concatenate([getattr(part, name) for part in parts])
                      for name in ("particle", "wall", "distances", "sigma")))


def wall_net_forces(n: int, d: int, particle: np.ndarray, wall: np.ndarray,
                    forces: np.ndarray) -> np.ndarray:
    """Net force of the walls on every particle, shape (N, d): f e_w per contact."""
    total = np.zeros((n, d))
    sign = 1.0 - 2.0 * (wall % 2)
    np.add.at(total, (particle, wall // 2), sign * forces)
    return total


def wall_equilibrium_columns(n: int, d: int, particle: np.ndarray, wall: np.ndarray):
    """The (n·d, K) sparse columns of the equilibrium matrix for K wall contacts: column k
    holds e_w in the rows of its particle (`calippso.contacts.equilibrium_matrix`)."""
    sign = 1.0 - 2.0 * (wall % 2)
    return sp.csr_matrix((sign, (particle * d + wall // 2, np.arange(particle.shape[0]))),
                         shape=(n * d, particle.shape[0]))


def wall_loads(d: int, wall: np.ndarray, forces: np.ndarray) -> np.ndarray:
    """The force the particles exert on every wall, along its axis, shape (d, 2).

    Entry (μ, 0) is the μ-component of the total force on the wall at 0 (≤ 0: pushed out of
    the box), (μ, 1) that on the wall at L_μ (≥ 0); a row of zeros for an axis without walls
    or without wall contacts. In balance, the two entries of a row sum to zero.
    """
    loads = np.zeros(2 * d)
    sign = 1.0 - 2.0 * (wall % 2)
    np.add.at(loads, wall, -sign * forces)
    return loads.reshape(d, 2)



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
    search : calippso.neighbors.NeighborSearch
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
