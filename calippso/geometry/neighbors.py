"""Periodic pair search: every pair of particles closer than a cutoff, without any N×N array.

Built on `scipy.spatial.cKDTree` with `boxsize`, which applies the minimum-image convention
along the periodic axes (a side of 0 leaves an axis bounded by walls or a cylinder open:
the optional mask `periodic`, shape (d,), bool, None for every axis periodic).
Why it exists: it is the one pair search of the numpy code (the jamming loop, the analysis,
the checks of inputs and of generated packings), which queries each configuration a few
times. The Numba loops keep their own lists (`generators.cells`, and
`generators.spherocylinders.cells` for rods), rebuilt inside compiled code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .periodic import minimum_image, wrap

__all__ = ["Pairs", "PairList", "NeighborSearch", "pairs_within", "close_pairs", "min_gap",
           "contact_shrink", "shrink_to_margin", "check_no_duplicates", "CONTACT_MARGIN",
           "NEAR_CONTACT_SLACK", "SAME_PLACE"]

#: Relative gap that `contact_shrink` leaves on the closest pair: far above the round-off of
#: |r|/σ, far below any gap that matters to a start.
CONTACT_MARGIN = 1e-9
#: `NeighborSearch.pairs_near_contact` reaches this fraction beyond the largest diameter, so
#: that a pair at contact up to round-off is never missed by the cutoff.
NEAR_CONTACT_SLACK = 1e-6
#: Two centres closer than this, in mean diameters, sit at the same place
#: (`check_no_duplicates`): no shrink of the diameters can separate them.
SAME_PLACE = 1e-12


@dataclass(frozen=True)
class Pairs:
    """A list of particle pairs with their minimum-image geometry.

    Attributes
    ----------
    i, j : ndarray, shape (M,), int64
        Particle indices with i < j.
    vectors : ndarray, shape (M, d)
        Minimum-image separation r_i − r_j, in length units.
    distances : ndarray, shape (M,)
        |r_i − r_j|.
    sigma : ndarray, shape (M,)
        Contact distance σ_ij = (σ_i + σ_j)/2.
    """

    i: np.ndarray
    j: np.ndarray
    vectors: np.ndarray
    distances: np.ndarray
    sigma: np.ndarray

    def __len__(self) -> int:
        return int(self.i.shape[0])

    @property
    def gaps(self) -> np.ndarray:
        """Relative gaps h_ij = |r_ij|/σ_ij − 1 (negative for an overlap), shape (M,)."""
        return self.distances / self.sigma - 1.0

    def smallest_gap(self) -> float:
        """The smallest relative gap h_ij, +inf when there is no pair."""
        return float(self.gaps.min()) if len(self) else float("inf")

    def subset(self, mask: np.ndarray) -> "Pairs":
        """The pairs selected by a boolean mask or an index array."""
        return Pairs(self.i[mask], self.j[mask], self.vectors[mask], self.distances[mask],
                     self.sigma[mask])


@dataclass(frozen=True, eq=False)
class PairList:
    """Every pair of one configuration within a cutoff (a Verlet list), to answer the pair
    queries of nearby configurations without a new tree (`NeighborSearch`).

    Attributes
    ----------
    positions : ndarray, shape (N, d)
        The wrapped centres the list was made at.
    cutoff : float
        Largest centre distance listed, length units.
    i, j : ndarray, shape (M,), int64
        The listed pairs, i < j, sorted by (i, j).
    """

    positions: np.ndarray
    cutoff: float
    i: np.ndarray
    j: np.ndarray


class NeighborSearch:
    """A periodic KD-tree over one configuration, for repeated pair queries.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (wrapped into the box on construction).
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    periodic : ndarray, shape (d,), bool, optional
        Periodic axes; None: all of them. Positions along the other axes are taken as they
        are (inside [0, L]).
    pair_list : PairList, optional
        The pairs of a nearby configuration within a larger cutoff: a query up to that cutoff
        less twice the largest displacement since is answered from the list (a pair that is
        closer than c now was closer than c + 2 × that displacement then), others by the tree.
    """

    def __init__(self, positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                 periodic: np.ndarray | None = None, pair_list: PairList | None = None):
        self.box = np.asarray(box, dtype=np.float64)
        self.periodic = None if periodic is None or np.all(periodic) else np.asarray(
            periodic, dtype=bool)
        self.positions = wrap(np.asarray(positions, dtype=np.float64), self.box, self.periodic)
        self.diameters = np.asarray(diameters, dtype=np.float64)
        self.d = self.positions.shape[1]
        self._kd_tree: cKDTree | None = None
        self._nearest: tuple[np.ndarray, np.ndarray] | None = None
        self.listed = pair_list
        self._drift: float | None = None

    @property
    def _tree(self) -> cKDTree:
        """The KD-tree, built on first use (a search served by its pair list needs none)."""
        if self._kd_tree is None:
            self._kd_tree = cKDTree(self.positions, boxsize=self.periodic_sides)
        return self._kd_tree

    def pair_list(self, cutoff: float) -> PairList:
        """The pairs of this configuration within `cutoff` (length units), for the searches
        of configurations near it."""
        pairs = self.pairs_within(cutoff)
        return PairList(self.positions, float(cutoff), pairs.i, pairs.j)

    def listed_reach(self) -> float:
        """The largest cutoff that the pair list answers (0 without one): its cutoff less
        twice the largest displacement of a centre since it was made."""
        if self.listed is None:
            return 0.0
        if self._drift is None:
            moved = minimum_image(self.positions - self.listed.positions, self.box,
                                  self.periodic)
            self._drift = float(np.sqrt(np.einsum("nd,nd->n", moved, moved)).max(initial=0.0))
        return self.listed.cutoff - 2.0 * self._drift

    @property
    def periodic_sides(self) -> np.ndarray:
        """The box sides of the periodic axes and 0 for the others (cKDTree's `boxsize`)."""
        return self.box if self.periodic is None else np.where(self.periodic, self.box, 0.0)

    @property
    def half_period(self) -> float:
        """Half the smallest periodic side (+inf with no periodic axis): the largest cutoff
        under which the minimum image is unique."""
        sides = self.box if self.periodic is None else self.box[self.periodic]
        return 0.5 * float(sides.min()) if sides.size else float("inf")

    def pairs_within(self, cutoff: float) -> Pairs:
        """All pairs whose centre distance is at most `cutoff` (below half the smallest
        periodic side).

        Returns
        -------
        Pairs
            Sorted by (i, j), with i < j.
        """
        if not cutoff < self.half_period:
            raise ValueError(
                f"pair cutoff {cutoff:g} is not below half the smallest periodic box side "
                f"{2 * self.half_period:g}"
            )
        if cutoff <= self.listed_reach():
            listed = self.pairs_of(self.listed.i, self.listed.j)
            return listed.subset(listed.distances <= cutoff)
        ij = self._tree.query_pairs(cutoff, output_type="ndarray").astype(np.int64, copy=False)
        if ij.shape[0]:
            ij.sort(axis=1)
            ij = ij[np.lexsort((ij[:, 1], ij[:, 0]))]
        return self.pairs_of(ij[:, 0], ij[:, 1])

    def pairs_near_contact(self) -> Pairs:
        """Every pair that touches or overlaps, and the nearly touching ones: centre distance
        at most the largest diameter × (1 + `NEAR_CONTACT_SLACK`).

        Returns
        -------
        Pairs
            Sorted by (i, j), with i < j; their `Pairs.gaps` hold every negative gap of the
            configuration.
        """
        return self.pairs_within(float(self.diameters.max()) * (1.0 + NEAR_CONTACT_SLACK))

    def pairs_of(self, i: np.ndarray, j: np.ndarray) -> Pairs:
        """Geometry of given pairs (index arrays of equal length, i < j)."""
        vectors = minimum_image(self.positions[i] - self.positions[j], self.box, self.periodic)
        distances = np.sqrt(np.einsum("md,md->m", vectors, vectors))
        sigma = 0.5 * (self.diameters[i] + self.diameters[j])
        return Pairs(i, j, vectors, distances, sigma)

    def nearest_neighbours(self) -> tuple[np.ndarray, np.ndarray]:
        """Distance to, and index of, every particle's nearest neighbour; shapes (N,), (N,)."""
        if self._nearest is None:
            distances, indices = self._tree.query(self.positions, k=2)
            self._nearest = (distances[:, 1], indices[:, 1])
        return self._nearest


def pairs_within(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                 cutoff: float, periodic: np.ndarray | None = None) -> Pairs:
    """All pairs whose centre-to-centre distance is at most `cutoff`.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    cutoff : float
        Largest centre distance kept, in length units; must be below half the smallest
        periodic box side so that the minimum image is unique.
    periodic : ndarray, shape (d,), bool, optional
        Periodic axes; None: all of them.

    Returns
    -------
    Pairs
        Sorted by (i, j).
    """
    return NeighborSearch(positions, diameters, box, periodic).pairs_within(cutoff)


def close_pairs(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
                max_gap: float, periodic: np.ndarray | None = None) -> Pairs:
    """Pairs with surface separation |r_ij| − σ_ij ≤ `max_gap` (length units), overlaps included.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
    diameters : ndarray, shape (N,)
    box : ndarray, shape (d,)
    max_gap : float
        Largest surface-to-surface distance kept, in length units (≥ 0).
    periodic : ndarray, shape (d,), bool, optional
        Periodic axes; None: all of them.
    """
    reach = float(np.max(diameters)) + max_gap
    pairs = pairs_within(positions, diameters, box, reach, periodic)
    return pairs.subset(pairs.distances - pairs.sigma <= max_gap)


def min_gap(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray,
            periodic: np.ndarray | None = None) -> tuple[float, int]:
    """Smallest relative gap h_ij = |r_ij|/σ_ij − 1 over all touching or overlapping pairs
    (`periodic`: the periodic axes, None for all).

    Returns
    -------
    (float, int)
        The smallest gap among pairs within contact range (+inf if no pair is that close)
        and the number of overlapping pairs (h < 0).
    """
    pairs = close_pairs(positions, diameters, box, 0.0, periodic)
    if len(pairs) == 0:
        return float("inf"), 0
    gaps = pairs.gaps
    return float(gaps.min()), int(np.count_nonzero(gaps < 0))


def contact_shrink(positions: np.ndarray, diameters: np.ndarray, box: np.ndarray) -> float:
    """Factor on all diameters that removes every overlap, one shrink for the whole packing.

    Scaled by it, the closest pair is left a relative gap of about `CONTACT_MARGIN`: a Poisson
    start, whose closest centres nearly coincide, shrinks to a tiny packing fraction.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (length units; wrapped or not).
    diameters : ndarray, shape (N,)
        Diameters (length units).
    box : ndarray, shape (d,)
        Periodic box sides (length units).

    Returns
    -------
    float
        min(1, (1 + h_min)(1 − `CONTACT_MARGIN`)), with h_min = |r_ij|/σ_ij − 1 the smallest
        relative gap of the touching or overlapping pairs (`min_gap`): 1.0 when no pair
        touches.
    """
    gap, _ = min_gap(positions, diameters, box)
    return shrink_to_margin(gap)


def shrink_to_margin(gap: float, margin: float = CONTACT_MARGIN) -> float:
    """Factor on all diameters that leaves a pair of relative gap `gap` a relative gap of
    about `margin`, and never grows them: min(1, (1 + gap)(1 − margin)).

    Parameters
    ----------
    gap : float
        Relative gap h = |r|/σ − 1 of the closest pair (negative for an overlap).
    margin : float
        Relative gap left on that pair (dimensionless, ≥ 0).
    """
    return min(1.0, (1.0 + gap) * (1.0 - margin))


def check_no_duplicates(positions: np.ndarray, box: np.ndarray, resolution: float,
                        periodic: np.ndarray | None = None) -> None:
    """ValueError naming two particles whose centres coincide (closer than `resolution`).

    An overlapping configuration can be shrunk to contact, or is refused with its own message
    by `calippso.jam`; two particles at the same place cannot be separated by any shrink.

    Parameters
    ----------
    positions : ndarray, shape (N, d)
        Centres (length units; wrapped or not).
    box : ndarray, shape (d,)
        Periodic box sides (length units).
    resolution : float
        Centres closer than this (length units) count as the same place; `SAME_PLACE` ×
        the mean diameter is the rule of `calippso.jam` and the generators.
    periodic : ndarray, shape (d,), bool, optional
        Periodic axes; None: all of them.
    """
    box = np.asarray(box, dtype=np.float64)
    sides = box if periodic is None else np.where(periodic, box, 0.0)
    tree = cKDTree(wrap(np.asarray(positions, dtype=np.float64), box, periodic), boxsize=sides)
    pairs = tree.query_pairs(resolution, output_type="ndarray")
    if pairs.shape[0]:
        i, j = sorted(int(k) for k in pairs[np.lexsort(pairs.T[::-1])][0])
        raise ValueError(f"duplicated particles in the input: particles {i} and {j} sit at "
                         f"the same position {np.asarray(positions)[i].tolist()} (modulo the "
                         f"box); {pairs.shape[0]} such pair(s)")
