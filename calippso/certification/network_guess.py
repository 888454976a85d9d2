"""Candidate contact networks of a near-jammed configuration, read from its geometry.

Close to a jamming point the contacts are the pairs with the smallest relative gaps
h = |r|/σ − 1: they sit within the distance to the jamming point (~1e-7 for a slightly
perturbed jammed packing), the next pairs usually orders of magnitude further, beyond the
largest jump of the sorted gaps. After recursive rattler removal the contacts form an
isostatic network, N_c = d (N_s − 1) + 1, and the Newton stage (`calippso.certification.newton`) can prove
its jamming point with no LP. The candidates, in order: a network handed over by the caller
(a hint, e.g. the overlap network of a soft-sphere quench) together with the pairs nearly as
close as its farthest contact; the fewest closest pairs that make an isostatic network, when
they all lie within `NEAR_CONTACT_GAP` of contact (in d = 5 the gaps above the contacts rise
smoothly, with no clear jump); the pairs below the largest jumps of the sorted gaps.

A candidate may hold a few pairs too many (hyperstatic) or be a few pairs off the jammed
network: `calippso.certification.network_first` settles it with the LP restricted to its pairs and the
Newton stage, and the certificate decides.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..geometry.contacts import isostaticity_gap, remove_rattlers
from ..geometry.neighbors import NeighborSearch, Pairs
from .restricted_lp import MAX_OPEN_CONTACTS

__all__ = ["CANDIDATE_GAP", "Candidate", "candidate_networks", "check_network_hint",
           "gap_splits", "fewest_not_hypostatic"]

#: A hint may miss at most this many contacts (after rattler removal) to be a candidate: the
#: restricted LP then finds its pairs too few and reads those farther from contact
#: (`calippso.certification.network_first`). A hint that misses more is not near the jammed
#: network.
MAX_MISSING_CONTACTS = 64
#: Pairs with a relative gap h below this are candidates for contacts. A near-jammed input has
#: its contacts within ~1e-6 of closing; 1e-3 leaves room for the jump above them.
CANDIDATE_GAP = 1e-3
#: Relative gaps below this count as zero on the logarithmic scale of the jumps (round-off).
ROUNDOFF_GAP = 1e-15
#: A split of the sorted gaps is a candidate only where they jump by at least this factor.
MIN_JUMP_RATIO = 3.0
#: Splits of the gap spectrum tried, the largest jumps first.
SPLITS_TRIED = 3
#: The smallest gaps that make an isostatic network are a candidate too, jump or not, when
#: the largest of them is below this relative gap: the contacts of a near-jammed input lie
#: within ~1e-7 of closing (an LS slow end to p = 1e7, a quench shrunk by its overlaps), those
#: of a compressed LS state (p ≤ 1e5, gaps ~1e-5) do not.
NEAR_CONTACT_GAP = 1e-6
#: A hint's candidate also holds the pairs with gaps below this factor times its largest
#: contact gap: near-contacts that may close on the way to the jamming point, which for a
#: quench shrunk from pressure p lie up to ~10 p from contact; a narrower band leaves the
#: restricted LP unbounded and costs a widening round. Later rounds read the pairs within
#: the same factor of every candidate's largest gap.
NEAR_PAIR_FACTOR = 32.0
#: A candidate read from the gap spectrum that is hyperstatic by more than this many contacts
#: is not tried: such a network is a crystal or a compressed state, not a jamming point with
#: a few near-contacts. (A hint is tried whatever its excess, up to the limit of
#: `calippso.certification.restricted_lp`, and when it misses contacts, up to
#: `MAX_MISSING_CONTACTS` of them.)
MAX_EXCESS_CONTACTS = 12


@dataclass(frozen=True, eq=False)
class Candidate:
    """Pairs that may hold the contact network of a near-jammed configuration.

    Attributes
    ----------
    pairs : Pairs
        The candidate pairs, with their geometry at the input.
    source : str
        "hint" (the network handed to `jam`, with its near pairs) or "gap spectrum".
    near_gap : float
        Relative gap below which pairs are read again as candidates in later rounds
        (`NEAR_PAIR_FACTOR` × the largest gap of the candidate's pairs, at most
        `CANDIDATE_GAP`).
    """

    pairs: Pairs
    source: str
    near_gap: float

    @property
    def key(self) -> bytes:
        """The sorted pair keys i·2³² + j, as bytes (identifies the candidate)."""
        return np.sort((self.pairs.i << 32) | self.pairs.j).tobytes()


def check_network_hint(network, n: int) -> np.ndarray:
    """A network hint as sorted unique pairs (i < j), shape (M, 2), int64.

    Raises
    ------
    ValueError
        The hint is not an (M, 2) array of particle indices in [0, N) with i ≠ j.
    """
    pairs = np.asarray(network)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not np.issubdtype(pairs.dtype, np.integer):
        raise ValueError(f"network must be an (M, 2) integer array of particle pairs, got "
                         f"shape {pairs.shape} and dtype {pairs.dtype}")
    if pairs.size and (pairs.min() < 0 or pairs.max() >= n):
        raise ValueError(f"network holds particle indices outside [0, {n})")
    if np.any(pairs[:, 0] == pairs[:, 1]):
        raise ValueError("network pairs a particle with itself")
    return np.unique(np.sort(pairs.astype(np.int64), axis=1), axis=0)


def candidate_networks(search: NeighborSearch, d: int,
                       hint: np.ndarray | None = None) -> list[Candidate]:
    """Candidate contact networks of a configuration, the most likely first.

    Parameters
    ----------
    search : NeighborSearch
        The configuration (any length unit).
    d : int
        Dimension.
    hint : ndarray, shape (M, 2), optional
        A network handed over by the caller (`check_network_hint`); tried first, with the
        pairs whose gaps are below `NEAR_PAIR_FACTOR` × its largest.

    Returns
    -------
    list of Candidate
        Distinct candidates that are neither hypostatic after rattler removal nor
        hyperstatic by more than `MAX_EXCESS_CONTACTS` when read from the gap spectrum (a
        hint may miss up to `MAX_MISSING_CONTACTS` contacts): the hint's; the
        fewest closest pairs that make an isostatic network, if all their gaps are below
        `NEAR_CONTACT_GAP`; then one per split of the gap spectrum (the `SPLITS_TRIED`
        largest jumps). Empty when nothing qualifies.
    """
    n = search.positions.shape[0]
    close = search.pairs_within(float(search.diameters.max()) * (1.0 + CANDIDATE_GAP))
    close = close.subset(close.gaps < CANDIDATE_GAP)
    ranked = close.subset(np.argsort(close.gaps, kind="stable"))
    candidates: list[Candidate] = []
    if hint is not None and hint.shape[0]:
        hinted = search.pairs_of(hint[:, 0], hint[:, 1])
        near_gap = _near_gap(hinted)
        near = close.subset(close.gaps < near_gap)
        pairs = np.unique(np.concatenate([hint, np.column_stack([near.i, near.j])]), axis=0)
        candidates.append(Candidate(search.pairs_of(pairs[:, 0], pairs[:, 1]), "hint",
                                    near_gap))
    isostatic = _isostatic_count(ranked, n, d)
    near = isostatic > 0 and ranked.gaps[isostatic - 1] < NEAR_CONTACT_GAP
    for count in ([isostatic] if near else []) + gap_splits(ranked.gaps, n, d):
        pairs = ranked.subset(np.arange(count))
        candidates.append(Candidate(pairs, "gap spectrum", _near_gap(pairs)))
    unique: list[Candidate] = []
    seen: set[bytes] = set()
    for candidate in candidates:
        excess = _excess(candidate.pairs, n, d)
        hinted = candidate.source == "hint"
        limit = MAX_OPEN_CONTACTS if hinted else MAX_EXCESS_CONTACTS
        lowest = -MAX_MISSING_CONTACTS if hinted else 0
        if lowest <= excess <= limit and candidate.key not in seen:
            seen.add(candidate.key)
            unique.append(candidate)
    return unique


def gap_splits(sorted_gaps: np.ndarray, n: int, d: int) -> list[int]:
    """Contact counts at the largest jumps of the sorted gaps, largest jump first.

    Only counts from N to 2 d N are looked at (an isostatic network of N particles has about
    d N contacts, fewer by the rattlers'), and only jumps of at least `MIN_JUMP_RATIO`.
    """
    if sorted_gaps.size < 2:
        return []
    logs = np.log10(np.maximum(sorted_gaps, ROUNDOFF_GAP))
    jumps = np.diff(logs)                     # jumps[k]: between pair k and pair k + 1
    counts = np.arange(1, sorted_gaps.size)   # the count of contacts below jumps[k]
    allowed = (counts >= n) & (counts <= 2 * d * n) & (jumps >= np.log10(MIN_JUMP_RATIO))
    best = np.flatnonzero(allowed)[np.argsort(-jumps[allowed], kind="stable")]
    return [int(counts[k]) for k in best[:SPLITS_TRIED]]


def _isostatic_count(ranked: Pairs, n: int, d: int) -> int:
    """The smallest count k of the closest pairs whose network, after rattler removal, is not
    hypostatic; 0 if even all pairs are hypostatic."""
    def excess(count: int) -> int:
        rattlers, kept = remove_rattlers(n, d, ranked.i[:count], ranked.j[:count])
        n_stable = int(n - rattlers.sum())
        return isostaticity_gap(int(kept.sum()), n_stable, d) if n_stable else -1

    return fewest_not_hypostatic(len(ranked), excess)


def fewest_not_hypostatic(size: int, excess: Callable[[int], int]) -> int:
    """The smallest count k ≤ `size` of the closest contacts whose network is not hypostatic,
    by bisection (`excess(k)`, the isostaticity gap of the closest k after rattler removal,
    grows with k up to the jumps of rattler removal); 0 if even all are hypostatic."""
    low, high = 1, size
    if high == 0 or excess(high) < 0:
        return 0
    while low < high:
        middle = (low + high) // 2
        if excess(middle) < 0:
            low = middle + 1
        else:
            high = middle
    return low


def _near_gap(pairs: Pairs) -> float:
    """`NEAR_PAIR_FACTOR` × the largest gap of the pairs, at most `CANDIDATE_GAP`."""
    largest = max(float(pairs.gaps.max(initial=0.0)), ROUNDOFF_GAP)
    return min(NEAR_PAIR_FACTOR * largest, CANDIDATE_GAP)


def _excess(pairs: Pairs, n: int, d: int) -> int:
    """The isostaticity gap of the pairs after rattler removal; below
    −`MAX_MISSING_CONTACTS` (never a candidate) if nothing is stable."""
    rattlers, kept = remove_rattlers(n, d, pairs.i, pairs.j)
    n_stable = int(n - rattlers.sum())
    if not n_stable:
        return -MAX_MISSING_CONTACTS - 1
    return isostaticity_gap(int(kept.sum()), n_stable, d)
