"""Candidate contact networks of a near-jammed packing in a container (flat walls, cylinder).

The network-first stage in a container: the contacts of a near-jammed packing are the
particle pairs and the particle–wall pairs with the smallest relative gaps, below the largest
jump of their sorted gaps (`calippso.certification.network_guess` reads pairs only, for periodic boxes).
Pair gaps h = |r|/σ − 1 and wall gaps δ/σ_w − 1 are ranked together. A candidate is the
closest contacts up to such a jump, or the fewest closest that make an isostatic network
(N_c = d N_s + 1 − zero modes, wall contacts counted) when they all lie within
`calippso.certification.network_guess.NEAR_CONTACT_GAP` of contact. Only candidates that are exactly
isostatic after rattler removal are returned: `jam` hands each to the Newton stage
(`calippso.certification.certificate.certify_network`), whose certificate decides, and runs the LP loop when
none is certified.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.boundaries import Boundaries
from ..geometry.contacts import isostaticity_gap
from ..geometry.neighbors import NeighborSearch, Pairs
from .network_guess import (CANDIDATE_GAP, NEAR_CONTACT_GAP, fewest_not_hypostatic,
                            gap_splits)
from ..geometry.rattlers import remove_rattlers
from ..geometry.walls import WallRows, wall_rows_within

__all__ = ["ContainerCandidate", "container_candidates"]


@dataclass(frozen=True, eq=False)
class ContainerCandidate:
    """An isostatic contact network guessed from the gaps of a packing in a container.

    Attributes
    ----------
    pairs : Pairs
        Its particle contacts (between stable particles), with their geometry at the input.
    walls : WallRows
        Its wall contacts (of stable particles).
    rattlers : ndarray, shape (N,), bool
    largest_gap : float
        The largest relative gap of its contacts at the input.
    """

    pairs: Pairs
    walls: WallRows
    rattlers: np.ndarray
    largest_gap: float


def container_candidates(search: NeighborSearch,
                         boundaries: Boundaries) -> list[ContainerCandidate]:
    """Isostatic candidate networks of a configuration in a container, the most likely first.

    Parameters
    ----------
    search : NeighborSearch
        The configuration (any length unit), with the container's periodic axes.
    boundaries : Boundaries
        The container (not periodic along every axis).

    Returns
    -------
    list of ContainerCandidate
        Distinct candidates, isostatic after rattler removal: the fewest closest contacts
        that make an isostatic network if all lie below `NEAR_CONTACT_GAP`, then one per
        large jump of the sorted gaps. Empty when none qualifies.
    """
    n, d = search.positions.shape
    close = search.pairs_within(float(search.diameters.max()) * (1.0 + CANDIDATE_GAP))
    close = close.subset(close.gaps < CANDIDATE_GAP)
    walls = wall_rows_within(search.positions, search.diameters, search.box, boundaries, 0.0,
                             1.0 + CANDIDATE_GAP)
    walls = walls.subset(walls.gaps < CANDIDATE_GAP)
    gaps = np.concatenate([close.gaps, walls.gaps])
    order = np.argsort(gaps, kind="stable")
    m = len(close)

    def network(count: int) -> ContainerCandidate:
        chosen = order[:count]
        pairs = close.subset(np.sort(chosen[chosen < m]))
        contacts = walls.subset(np.sort(chosen[chosen >= m] - m))
        rattlers, kept = remove_rattlers(n, d, pairs.i, pairs.j, contacts.particle)
        largest = float(gaps[chosen].max(initial=0.0))
        return ContainerCandidate(pairs.subset(kept),
                                  contacts.subset(~rattlers[contacts.particle]), rattlers,
                                  largest)

    def excess(candidate: ContainerCandidate) -> int:
        n_stable = int(n - candidate.rattlers.sum())
        if not n_stable:
            return -1
        return isostaticity_gap(len(candidate.pairs) + len(candidate.walls), n_stable, d,
                                boundaries.zero_modes)

    counts = []
    isostatic = fewest_not_hypostatic(gaps.size, lambda count: excess(network(count)))
    if isostatic and gaps[order[isostatic - 1]] < NEAR_CONTACT_GAP:
        counts.append(isostatic)
    counts += gap_splits(gaps[order], n, d)
    candidates, seen = [], set()
    for count in counts:
        candidate = network(count)
        if excess(candidate) == 0 and count not in seen:
            seen.add(count)
            candidates.append(candidate)
    return candidates
