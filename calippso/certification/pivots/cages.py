"""The cage test of a pivot: where along a floppy mode a rattler's cage closes on it.

The ratio test (`geometry.find_closing_pairs`) reads the pairs of stable particles; the
rattlers stand still along the mode and are moved out of the way afterwards. A cage that
closes before the first pair does is a pair of the ratio test too: there its rattler
touches d + 1 particles, and joins the network with those contacts (d unknowns, d + 1 rows:
the network, one contact short after the release, is isostatic again). Rattlers near one
another share a cage: k of them close with k d + 1 pairs.

For each cage the test is a small LP in the rattlers' displacements δ (k d components) and
the step t (inflation units, as the ratio test's): maximise t subject to the linearised gaps
of the cage's pairs, Φ_q = |r_q + Δ_i − Δ_j|²/σ_q² − 1 − t ≥ 0, where Δ is δ on a rattler
and t m on a stable particle (m the mode), linearised again at the solution until t
settles (a sequence of LPs; the gaps are convex in δ, so each linearisation is
conservative). The pairs that bind at the optimum, the ones with nonzero duals, are the
contacts that close.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...geometry.neighbors import NeighborSearch, Pairs
from .geometry import RATTLER_REACH, closing_rates

__all__ = ["CageClosure", "closing_cages", "CAGE_GAP", "CAGE_LINEARISATIONS"]

#: Stable particles within this relative gap of a rattler form its cage in the test: beyond
#: the largest move of the rattler (2 √d `RATTLER_REACH` in d ≤ 5), so that no pair beyond
#: the cage can bind.
CAGE_GAP = 5e-2
#: Linearisations of the gaps at most per rattler; they stop earlier once the step changes
#: by less than `CAGE_STEP_TOLERANCE` (relative).
CAGE_LINEARISATIONS = 4
CAGE_STEP_TOLERANCE = 1e-6
#: Steps (inflation units) beyond this are no closure: a cage that would close only after
#: Γ doubled is not a correction of the network.
MAX_CAGE_STEP = 1.0
#: A pair binds at the optimum when its dual is above this, relative to the largest one.
BINDING_DUAL = 1e-9


@dataclass(frozen=True)
class CageClosure:
    """Rattlers whose common cage closes along the mode before the ratio test's pair.

    Attributes
    ----------
    rattlers : ndarray, shape (k,), int64
        The rattlers that the cage holds (one, or a few near one another).
    step : float
        The step t at which the cage closes (inflation units, linearised).
    displacements : ndarray, shape (k, d)
        The rattlers' displacements δ there (mean diameters).
    i, j : ndarray, shape (k d + 1,), int64
        The pairs that close on them, i < j.
    """

    rattlers: np.ndarray
    step: float
    displacements: np.ndarray
    i: np.ndarray
    j: np.ndarray


def closing_cages(search: NeighborSearch, stable: np.ndarray, mode: np.ndarray,
                  before: float) -> list[CageClosure]:
    """The cages that close along `mode` at a step below `before`, earliest first.

    A cage holds one rattler, or a few whose pairs are within `CAGE_GAP` of one another:
    they move together in the test.

    Parameters
    ----------
    search : NeighborSearch
        The vertex's configuration (mean diameters).
    stable : ndarray, shape (N,), bool
        The network's particles; the others are rattlers, still along the mode.
    mode : ndarray, shape (N, d)
        The floppy mode, per unit inflation (zero on the rattlers).
    before : float
        The step of the ratio test's first pair: only cages that close before it matter.

    Returns
    -------
    list of CageClosure
        Sorted by step; a cage whose closing pairs are not k d + 1 for the k rattlers they
        hold (a degenerate optimum, or a rattler held by `RATTLER_REACH`: it cannot be moved
        out of the way there) is left out.
    """
    cage = _cage_pairs(search, stable)
    cluster = _clusters(cage, stable)
    of_pair = np.where(stable[cage.i], cluster[cage.j], cluster[cage.i])
    # rattlers standing still are free until their first pair closes: no earlier closure
    rates = closing_rates(cage, _cage_motion(stable, mode))
    standing = np.full(len(cage), np.inf)
    closing = rates < 0
    standing[closing] = np.maximum(_phi(cage.vectors[closing], cage.sigma[closing]),
                                   0.0) / -rates[closing]
    flagged = np.unique(of_pair[standing < before])
    cap = min(before, MAX_CAGE_STEP)
    closures = _closures(cage, of_pair, cluster, flagged, stable, mode, cap)
    if closures is None:   # one cage's LP fails (a pair overlaps already): each on its own
        closures = [closure for label in flagged
                    for closure in _closures(cage, of_pair, cluster, label[None], stable,
                                             mode, cap) or []]
    return sorted(closures, key=lambda closure: closure.step)


def _cage_pairs(search: NeighborSearch, stable: np.ndarray) -> Pairs:
    """The pairs with a rattler within `CAGE_GAP` of contact."""
    pairs = search.pairs_within(float(search.diameters.max()) * (1.0 + CAGE_GAP))
    return pairs.subset(~(stable[pairs.i] & stable[pairs.j]) & (pairs.gaps < CAGE_GAP))


def _clusters(cage: Pairs, stable: np.ndarray) -> np.ndarray:
    """A label per particle, shape (N,): rattlers joined by pairs of `cage` share one
    (stable particles have their own)."""
    from scipy.sparse.csgraph import connected_components

    n = stable.shape[0]
    both = ~stable[cage.i] & ~stable[cage.j]
    links = sp.csr_matrix((np.ones(int(both.sum())), (cage.i[both], cage.j[both])),
                          shape=(n, n))
    return connected_components(links, directed=False)[1]


def _phi(vectors: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Φ = |r|²/σ² − 1 of each pair, shape (P,)."""
    return np.einsum("pd,pd->p", vectors, vectors) / sigma**2 - 1.0


def _cage_motion(stable: np.ndarray, mode: np.ndarray) -> np.ndarray:
    """The motion of each particle along the mode per unit step, shape (N, d): the mode on
    stable particles, zero on rattlers (theirs is δ)."""
    return np.where(stable, 1.0, 0.0)[:, None] * mode


def _closures(cage: Pairs, of_pair: np.ndarray, cluster: np.ndarray, labels: np.ndarray,
              stable: np.ndarray, mode: np.ndarray, cap: float) -> list[CageClosure] | None:
    """The largest step at which the rattlers of each cage in `labels` still fit it (module
    doc), all cages in one LP (they share no variable: each step is maximised on its own),
    capped at `cap`; the cages that close below it. None when the LP fails."""
    from scipy.optimize import linprog   # the LP solver, only when a cage may close

    if labels.size == 0:
        return []
    n, d = mode.shape
    chosen = np.isin(of_pair, labels)
    own = cage.subset(chosen)
    block = np.searchsorted(labels, of_pair[chosen])
    rattlers = np.flatnonzero(~stable & np.isin(cluster, labels))
    column = np.full(n, -1)
    column[rattlers] = d * np.arange(rattlers.size)
    n_steps = labels.size
    n_columns = d * rattlers.size + n_steps
    step_column = d * rattlers.size + block
    motion = _cage_motion(stable, mode)
    objective = np.zeros(n_columns)
    objective[d * rattlers.size:] = -1.0
    bounds = [(-RATTLER_REACH, RATTLER_REACH)] * (d * rattlers.size) + [(0.0, cap)] * n_steps
    here = np.zeros(n_columns)
    result = None
    for _ in range(CAGE_LINEARISATIONS):
        displacement = np.zeros((n, d))
        displacement[rattlers] = here[:d * rattlers.size].reshape(-1, d)
        steps = here[step_column]
        ends = [displacement[end] + steps[:, None] * motion[end] for end in (own.i, own.j)]
        vectors = own.vectors + ends[0] - ends[1]
        phi = _phi(vectors, own.sigma) - steps
        gradient = 2.0 * vectors / own.sigma[:, None] ** 2   # dΦ/d(x_i − x_j)
        rows, cols, values = [np.arange(len(own))], [step_column], [
            np.einsum("pd,pd->p", gradient, motion[own.i] - motion[own.j]) - 1.0]
        for end, sign in ((own.i, 1.0), (own.j, -1.0)):
            held = np.flatnonzero(column[end] >= 0)
            rows.append(np.repeat(held, d))
            cols.append((column[end[held], None] + np.arange(d)).ravel())
            values.append((sign * gradient[held]).ravel())
        matrix = sp.csr_matrix((np.concatenate(values),
                                (np.concatenate(rows), np.concatenate(cols))),
                               shape=(len(own), n_columns))
        # Φ + g·(x − x_k) ≥ 0, x = (δ, t)
        result = linprog(objective, A_ub=-matrix, b_ub=phi - matrix @ here, bounds=bounds,
                         method="highs")
        if result.status != 0:
            return None
        previous, here = steps, result.x
        if np.all(np.abs(here[step_column] - previous)
                  <= CAGE_STEP_TOLERANCE * here[step_column]):
            break
    duals = np.abs(result.ineqlin.marginals)
    steps = here[d * rattlers.size:]
    closures = []
    for index, label in enumerate(labels):
        if not steps[index] < cap:
            continue
        pairs = np.flatnonzero(block == index)
        binding = pairs[duals[pairs] > BINDING_DUAL * duals[pairs].max(initial=0.0)]
        # the rattlers that the binding pairs hold (others of the cluster stay free)
        held = np.intersect1d(rattlers, np.concatenate([own.i[binding], own.j[binding]]))
        if binding.size != held.size * d + 1:
            continue
        displacements = here[(column[held, None] + np.arange(d))]
        closures.append(CageClosure(held.astype(np.int64), float(steps[index]),
                                    displacements, own.i[binding].astype(np.int64),
                                    own.j[binding].astype(np.int64)))
    return closures
