"""Settle a candidate network of a near-jammed input without a sparse LP: the restricted LP
chooses the contacts, Newton solves them, and a few rounds repair what is off.

Round 0 takes a candidate from `calippso.certification.network_guess` (pairs that may be hyperstatic by a
few, or a few pairs off the jammed network). When ``pivots`` is on, a candidate that is
isostatic as it is (a hint that names exactly the contacts) goes straight to Newton and the
pivots of step 4. Each round

1. keeps the candidate pairs with a positive multiplier at the optimum of the CALiPPSO LP
   restricted to them (`calippso.certification.restricted_lp`): an isostatic network;
2. solves its contact equations by Newton (`calippso.certification.newton`), from the input in the
   first round and from the previous round's jamming point after that;
3. accepts the network when every force is positive and no other pair of stable particles
   overlaps at that jamming point;
4. when no other pair overlaps but some forces are not positive, and ``pivots`` is on,
   follows the contact pivots of `calippso.certification.pivots` from that point: each releases one such
   contact and closes the next pair on the exact geometry, until every force is positive.
Otherwise the next round reads the candidates at that point (the pairs within `near_gap` of
contact: the network, the pairs that overlap, those about to close) and the restricted LP,
linearised there, chooses again.

When the candidate pairs cannot hold a positive self-stress (the restricted LP is
unbounded: a hint that misses contacts, or pairs that close on the way to the jamming
point), a pair that must close is missing: the round reads the pairs `WIDENING` times
farther from contact instead (never beyond `calippso.certification.network_guess.CANDIDATE_GAP`).

The pivots of all rounds (and of all the candidates the stage tries) share one budget of
wall time, `STAGE_PIVOT_FACTORIZATIONS` sparse LU factorisations of the first network's
Jacobian: a network that needs more is too far off for one contact at a time.

This is the loop of `calippso.ilp` with only near pairs as rows and Newton as the update.
The caller (`jam`) still certifies the accepted network (overlaps, rattlers, the touching
test) before it ends a run with no LP.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..geometry.contacts import isostaticity_gap, remove_rattlers
from ..geometry.neighbors import NeighborSearch, Pairs
from ..geometry.packing import minimum_image
from .certificate import NEWTON_OVERLAP_TOLERANCE
from .network_guess import CANDIDATE_GAP, Candidate
from .newton import NEWTON_FAILED, Refinement, refine_isostatic
from .pivots import PivotPath, pivot_to_jamming
from .pivots.path import PivotHook
from .restricted_lp import TOO_FEW, lp_network
from .sparse_lu import tally

__all__ = ["MAX_ROUNDS", "STAGE_PIVOT_FACTORIZATIONS", "PivotBudget", "SettledNetwork", "settle_candidate"]

#: Rounds of restricted LP and Newton tried per candidate (each costs two or three sparse
#: factorisations); a near-jammed input settles in one to three.
MAX_ROUNDS = 6
#: When the candidate pairs hold no positive self-stress (the restricted LP is unbounded:
#: a pair that closes on the way to the jamming point is missing), the pairs within this
#: factor farther from contact are read too, in a round of their own.
WIDENING = 4.0
#: Wall time of contact pivots that the network-first stage spends at most over all its
#: rounds and candidates, in sparse LU factorisations of its first network's Jacobian (the
#: first one timed on the run's machine, so that the budget follows the machine and N):
#: about two interior-point LPs of the same packing (one costs 30 to 75 such factorisations
#: at N = 8192 and 16384). The N = 8192 quench to p = 1e-6 of seed 1 settles after 179
#: pivots (106 s with no budget); a network that needs more is left to the LP loop, which
#: sees all of it at once.
STAGE_PIVOT_FACTORIZATIONS = 150


@dataclass
class PivotBudget:
    """Seconds of contact pivots still allowed to the network-first stage (shared by its
    candidates).

    Attributes
    ----------
    seconds : float or None
        Seconds left; None until `price` sets them (`STAGE_PIVOT_FACTORIZATIONS` times the
        first factorisation); `settle_candidate` stops a candidate once none are left.
    """

    seconds: float | None = None

    def price(self, factorization_seconds: float) -> None:
        """Set the budget from the time of one factorisation of the network's Jacobian (the
        first price holds)."""
        if self.seconds is None:
            self.seconds = STAGE_PIVOT_FACTORIZATIONS * factorization_seconds

    @property
    def spent(self) -> bool:
        return self.seconds is not None and self.seconds <= 0

    def per_path(self) -> float | None:
        """Seconds one path may take: what is left (None: not priced yet, no limit)."""
        return self.seconds

    def spend(self, path: PivotPath | None) -> None:
        """Count the wall time of a path (none when its start was refused)."""
        if path is not None and self.seconds is not None:
            self.seconds -= path.seconds

    def describe(self) -> str:
        return (f"the stage's {STAGE_PIVOT_FACTORIZATIONS} factorisations' worth of contact "
                f"pivots are spent")


@dataclass(frozen=True, eq=False)
class SettledNetwork:
    """An isostatic network whose Newton solution has positive forces and no overlap.

    Attributes
    ----------
    i, j : ndarray, shape (M,), int64
        Contacts between stable particles, i < j, with M = d (N_s − 1) + 1.
    rattlers : ndarray, shape (N,), bool
        Particles outside the network (fewer than d + 1 contacts, removed recursively).
    source : str
        The candidate's source ("hint" or "gap spectrum").
    rounds : int
        Rounds of restricted LP and Newton taken (1 when the first choice held).
    opened : int
        Candidate pairs that the first restricted LP left open.
    largest_gap : float
        Largest relative gap among the contacts at the input.
    refinement : Refinement
        The Newton solution (positions, diameters, forces), its growth and largest
        displacement measured from the input.
    pivots : PivotPath or None
        The contact pivots that ended the last round, if any.
    """

    i: np.ndarray
    j: np.ndarray
    rattlers: np.ndarray
    source: str
    rounds: int
    opened: int
    largest_gap: float
    refinement: Refinement
    pivots: PivotPath | None = None


def settle_candidate(search: NeighborSearch, candidate: Candidate, d: int,
                     pivots: bool = True, budget: PivotBudget | None = None,
                     on_pivot: PivotHook | None = None
                     ) -> tuple[SettledNetwork | None, str, Refinement | None]:
    """Rounds of restricted LP and Newton from a candidate (module doc).

    Parameters
    ----------
    search : NeighborSearch
        The input configuration (mean-diameter units).
    candidate : Candidate
        Pairs to choose from, at the input.
    d : int
        Dimension.
    pivots : bool
        Follow contact pivots from a round's network whose jamming point has non-positive
        forces and no overlap (`calippso.certification.pivots`), before another round.
    budget : PivotBudget, optional
        The seconds of pivots allowed (spent as they are taken); a fresh budget, priced on
        the first Newton solve, when omitted. A candidate is refused once the budget is
        spent and its network is not settled.
    on_pivot : PivotHook, optional
        Called after every contact pivot (`calippso.certification.pivots.pivot_to_jamming`).

    Returns
    -------
    (SettledNetwork or None, str, Refinement or None)
        The settled network, or None and why the last round failed; and the jamming point
        of the last network Newton solved (None if it solved none), with its rattlers
        unmoved: where a refused candidate got to.
    """
    n = search.positions.shape[0]
    current, base, near_gap = search, candidate.pairs, candidate.near_gap
    budget = PivotBudget() if budget is None else budget
    pairs, opened, failure, reached = base, -1, "", None
    for round_number in range(1, MAX_ROUNDS + 1):
        if pivots and budget.spent:
            return None, f"{budget.describe()} ({failure})", reached
        # an isostatic candidate leaves the restricted LP no choice: the pivots repair it
        direct = pivots and round_number == 1 and _solvable_as_it_is(pairs, n, d)
        closed, failure = ((np.ones(len(pairs), dtype=bool), "") if direct
                           else lp_network(pairs, n, d))
        if closed is None:
            if failure != TOO_FEW or near_gap >= CANDIDATE_GAP:
                break
            # pairs are missing: read those a little farther from contact
            near_gap = min(near_gap * WIDENING, CANDIDATE_GAP)
            pairs = _union(current, base, _near_pairs(current, near_gap))
            continue
        if opened < 0:
            opened = int(len(pairs) - closed.sum())
        rattlers, kept = remove_rattlers(n, d, pairs.i[closed], pairs.j[closed])
        i, j = pairs.i[closed][kept], pairs.j[closed][kept]
        if isostaticity_gap(i.shape[0], int(n - rattlers.sum()), d) != 0:
            return None, "the restricted LP's network is not isostatic", reached
        with tally() as cost:
            refined = refine_isostatic(current.positions, current.diameters, search.box, i, j,
                                       ~rattlers)
        if cost.factorizations:
            budget.price(cost.factorize_seconds / cost.factorizations)
        if refined is None and direct:
            continue   # the restricted LP chooses from the same pairs
        if refined is None:
            return None, NEWTON_FAILED, reached
        current = NeighborSearch(refined.positions, refined.diameters, search.box)
        reached = refined
        near = _near_pairs(current, near_gap)
        overlap = _overlaps_outside(near, i, j, rattlers).any()
        path = None
        if pivots and not refined.positive and not overlap:
            path, failure = pivot_to_jamming(current.positions, current.diameters,
                                             search.box, i, j, rattlers, refined=refined,
                                             time_limit=budget.per_path(),
                                             on_pivot=on_pivot)
            budget.spend(path)
            if path is not None:   # the next round starts where the pivots stopped
                i, j, rattlers, refined = path.i, path.j, path.rattlers, path.refinement
                current = NeighborSearch(refined.positions, refined.diameters, search.box)
                reached = refined
                near = _near_pairs(current, near_gap)
        if refined.positive and not overlap:
            gaps = search.pairs_of(i, j).gaps
            return SettledNetwork(i, j, rattlers, candidate.source, round_number, opened,
                                  float(gaps.max(initial=0.0)),
                                  _from_input(refined, search, rattlers), path), "", reached
        if not overlap and pivots:
            failure = f"a non-positive force; pivots: {failure}"
        else:
            failure = "a non-positive force" if not refined.positive else "an overlap"
        base, pairs = current.pairs_of(i, j), near
    return None, f"not settled in {MAX_ROUNDS} rounds ({failure})", reached


def _solvable_as_it_is(pairs: Pairs, n: int, d: int) -> bool:
    """Whether the pairs need no choice by the restricted LP: an isostatic network as they are
    (no pair of a rattler)."""
    rattlers, kept = remove_rattlers(n, d, pairs.i, pairs.j)
    gap = isostaticity_gap(int(kept.sum()), int(n - rattlers.sum()), d)
    return gap == 0 and bool(kept.all())


def _from_input(refined: Refinement, search: NeighborSearch,
                rattlers: np.ndarray) -> Refinement:
    """`refined` with its growth and largest displacement measured from the input (a later
    round starts from the previous round's jamming point)."""
    stable = ~rattlers
    moved = minimum_image(refined.positions[stable] - search.positions[stable], search.box)
    growth = float(np.mean(refined.diameters / search.diameters)) - 1.0
    return replace(refined, sqrt_gamma_minus_1=growth,
                   max_displacement=float(np.abs(moved).max(initial=0.0)))


def _near_pairs(search: NeighborSearch, near_gap: float) -> Pairs:
    """The pairs with relative gaps below `near_gap` (overlaps included)."""
    near = search.pairs_within(float(search.diameters.max()) * (1.0 + near_gap))
    return near.subset(near.gaps < near_gap)


def _union(search: NeighborSearch, first: Pairs, second: Pairs) -> Pairs:
    """The pairs of both lists, once each, with their geometry in `search`."""
    both = np.unique(np.column_stack([np.concatenate([first.i, second.i]),
                                      np.concatenate([first.j, second.j])]), axis=0)
    return search.pairs_of(both[:, 0], both[:, 1])


def _overlaps_outside(near: Pairs, i: np.ndarray, j: np.ndarray,
                      rattlers: np.ndarray) -> np.ndarray:
    """Which near pairs of two stable particles overlap without being a contact, shape (P,)."""
    n = rattlers.shape[0]
    outside = ~np.isin(near.i * n + near.j, i * n + j)
    stable = ~rattlers[near.i] & ~rattlers[near.j]
    return outside & stable & (near.gaps < -NEWTON_OVERLAP_TOLERANCE)
