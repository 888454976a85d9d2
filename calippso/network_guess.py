"""Candidate contact networks of a near-jammed configuration, read from its geometry.

Close to a jamming point the contacts are the pairs with the smallest relative gaps
h = |r|/σ − 1: they sit within the distance to the jamming point (~1e-7 for a slightly
perturbed jammed packing), the next pairs usually orders of magnitude further, beyond the
largest jump of the sorted gaps. After recursive rattler removal the contacts form an
isostatic network, N_c = d (N_s − 1) + 1, and the Newton stage (`calippso.newton`) can prove
its jamming point with no LP. The candidates, in order: a network handed over by the caller
(a hint, e.g. the overlap network of a soft-sphere quench); the fewest closest pairs that
make an isostatic network, when they all lie within `NEAR_CONTACT_GAP` of contact (in d = 5
the gaps above the contacts rise smoothly, with no clear jump); the pairs below the largest
jumps of the sorted gaps.

Not every near-jammed input has a clean jump: a candidate may hold a few near-contacts too
many (hyperstatic by a few). The pairs with the largest gaps are then dropped, one by one and
never one that would make a particle a rattler, until the count is isostatic. Each candidate
is only a guess: the certificate of the Newton stage decides.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .contacts import isostaticity_gap, remove_rattlers
from .neighbors import NeighborSearch, Pairs

__all__ = ["NetworkGuess", "guess_networks", "check_network_hint"]

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
#: A candidate hyperstatic by more than this many contacts is not trimmed: such a network is
#: a crystal or a compressed state, not a jamming point with a few near-contacts.
MAX_EXCESS_CONTACTS = 12


@dataclass(frozen=True, eq=False)
class NetworkGuess:
    """An isostatic candidate contact network.

    Attributes
    ----------
    i, j : ndarray, shape (M,), int64
        Contacts between stable particles, i < j, with M = d (N_s − 1) + 1.
    rattlers : ndarray, shape (N,), bool
        Particles with fewer than d + 1 contacts, removed recursively.
    source : str
        "hint" (the network handed to `jam`) or "gap spectrum".
    largest_gap : float
        Largest relative gap h among the contacts.
    dropped : int
        Candidate pairs dropped to make the network isostatic.
    """

    i: np.ndarray
    j: np.ndarray
    rattlers: np.ndarray
    source: str
    largest_gap: float
    dropped: int

    @property
    def key(self) -> bytes:
        """The sorted contact keys i N + j, as bytes (identifies the network)."""
        return np.sort(self.i * self.rattlers.size + self.j).tobytes()


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


def guess_networks(search: NeighborSearch, d: int,
                   hint: np.ndarray | None = None) -> list[NetworkGuess]:
    """Isostatic candidate networks of a configuration, the most likely first.

    Parameters
    ----------
    search : NeighborSearch
        The configuration (any length unit).
    d : int
        Dimension.
    hint : ndarray, shape (M, 2), optional
        A network handed over by the caller (`check_network_hint`); tried first.

    Returns
    -------
    list of NetworkGuess
        Distinct isostatic candidates: the hint's; the fewest closest pairs that make an
        isostatic network, if all their gaps are below `NEAR_CONTACT_GAP`; then one per split
        of the gap spectrum (the `SPLITS_TRIED` largest jumps). Each is trimmed
        of its largest-gap pairs when it is hyperstatic by at most `MAX_EXCESS_CONTACTS`.
        Empty when nothing qualifies.
    """
    n = search.positions.shape[0]
    close = search.pairs_within(float(search.diameters.max()) * (1.0 + CANDIDATE_GAP))
    close = close.subset(close.gaps < CANDIDATE_GAP)
    order = np.argsort(close.gaps, kind="stable")
    ranked = close.subset(order)
    candidates: list[tuple[Pairs, str]] = []
    if hint is not None and hint.shape[0]:
        candidates.append((search.pairs_of(hint[:, 0], hint[:, 1]), "hint"))
    isostatic = _isostatic_count(ranked, n, d)
    near = isostatic > 0 and ranked.gaps[isostatic - 1] < NEAR_CONTACT_GAP
    counts = ([isostatic] if near else []) + _splits(ranked.gaps, n, d)
    candidates += [(ranked.subset(np.arange(count)), "gap spectrum") for count in counts]
    guesses: list[NetworkGuess] = []
    seen: set[bytes] = set()
    for pairs, source in candidates:
        guess = _isostatic_network(pairs, n, d, source)
        if guess is not None and guess.key not in seen:
            seen.add(guess.key)
            guesses.append(guess)
    return guesses


def _splits(sorted_gaps: np.ndarray, n: int, d: int) -> list[int]:
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
    hypostatic (found by bisection; the excess grows with k up to the jumps of rattler
    removal); 0 if even all pairs are hypostatic."""
    def excess(count: int) -> int:
        rattlers, kept = remove_rattlers(n, d, ranked.i[:count], ranked.j[:count])
        n_stable = int(n - rattlers.sum())
        return isostaticity_gap(int(kept.sum()), n_stable, d) if n_stable else -1

    low, high = 1, len(ranked)
    if high == 0 or excess(high) < 0:
        return 0
    while low < high:
        middle = (low + high) // 2
        if excess(middle) < 0:
            low = middle + 1
        else:
            high = middle
    return low


def _isostatic_network(pairs: Pairs, n: int, d: int, source: str) -> NetworkGuess | None:
    """The candidate after rattler removal, trimmed to isostatic; None if it cannot be."""
    rattlers, kept = remove_rattlers(n, d, pairs.i, pairs.j)
    n_stable = int(n - rattlers.sum())
    excess = isostaticity_gap(int(kept.sum()), n_stable, d)
    if n_stable == 0 or excess < 0 or excess > MAX_EXCESS_CONTACTS:
        return None
    dropped = 0
    if excess > 0:
        kept = _trimmed(pairs, kept, n, d, excess)
        if kept is None:
            return None
        dropped = excess
    gaps = pairs.gaps[kept]
    return NetworkGuess(pairs.i[kept], pairs.j[kept], rattlers, source,
                        float(gaps.max(initial=0.0)), dropped)


def _trimmed(pairs: Pairs, kept: np.ndarray, n: int, d: int,
             excess: int) -> np.ndarray | None:
    """Drop `excess` kept pairs, the largest gaps first, never one whose removal would leave a
    particle with fewer than d + 1 contacts; None if too few pairs can go."""
    kept = kept.copy()
    counts = np.bincount(pairs.i[kept], minlength=n) + np.bincount(pairs.j[kept], minlength=n)
    for k in np.flatnonzero(kept)[np.argsort(-pairs.gaps[kept], kind="stable")]:
        if excess == 0:
            break
        a, b = pairs.i[k], pairs.j[k]
        if counts[a] > d + 1 and counts[b] > d + 1:
            kept[k] = False
            counts[a] -= 1
            counts[b] -= 1
            excess -= 1
    return kept if excess == 0 else None
