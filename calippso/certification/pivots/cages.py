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
from .geometry import RATTLER_REACH

__all__ = ["CageClosure", "closing_cages", "CAGE_GAP", "CAGE_LINEARISATIONS"]

#: Stable particles within this relative gap of a rattler form its cage in the test: beyond
#: the largest move of the rattler (2 √d `RATTLER_REACH` in d ≤ 5), so that no pair beyond
#: the cage can bind.
CAGE_GAP = 5e-2
#: Linearisations of the gaps at most per rattler; they stop earlier once the step changes
#: by less than `CAGE_STEP_TOLERANCE` (relative).
CAGE_LINEARISATIONS = 4
CAGE_STEP_TOLERANCE = 1e-6
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
    n, d = mode.shape
    cage = _cage_pairs(search, stable)
    cluster = _clusters(cage, stable)
    of_pair = np.where(stable[cage.i], cluster[cage.j], cluster[cage.i])
    # rattlers standing still are free until their first pair closes: no earlier closure
    standing_still = np.where(stable, 1.0, 0.0)[:, None] * mode
    rates = _rates(cage, standing_still)
    standing = np.full(len(cage), np.inf)
    closing = rates < 0
    standing[closing] = np.maximum(_phi(cage.vectors[closing], cage.sigma[closing]),
                                   0.0) / -rates[closing]
    closures = []
    for label in np.unique(of_pair[standing < before]):
        closure = _cage_closure(np.flatnonzero(cluster == label), cage.subset(of_pair == label),
                                stable, mode)
        if closure is not None and closure.step < before:
            closures.append(closure)
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


def _rates(pairs: Pairs, motion: np.ndarray) -> np.ndarray:
    """dΦ/dt of each pair under a motion per unit step (shape (N, d)), shape (P,)."""
    relative = motion[pairs.i] - motion[pairs.j]
    return 2.0 * np.einsum("pd,pd->p", pairs.vectors, relative) / pairs.sigma**2 - 1.0


def _cage_closure(rattlers: np.ndarray, own: Pairs, stable: np.ndarray,
                  mode: np.ndarray) -> CageClosure | None:
    """The largest step at which the rattlers still fit their moving cage (module doc)."""
    from scipy.optimize import linprog   # the LP solver, only when a cage may close

    k, d = rattlers.size, mode.shape[1]
    column = np.full(stable.shape[0], -1)
    column[rattlers] = d * np.arange(k)
    # the motion of each end of a pair along the mode (zero on rattlers: theirs is δ)
    cage_motion = np.where(stable, 1.0, 0.0)[:, None] * mode
    objective = np.zeros(k * d + 1)
    objective[-1] = -1.0
    bounds = [(-RATTLER_REACH, RATTLER_REACH)] * (k * d) + [(0.0, None)]
    displacements, step = np.zeros((k, d)), 0.0
    result = None
    for _ in range(CAGE_LINEARISATIONS):
        moved = np.zeros_like(mode)
        moved[rattlers] = displacements
        shift = moved + step * cage_motion
        vectors = own.vectors + shift[own.i] - shift[own.j]
        phi = _phi(vectors, own.sigma) - step
        gradient = 2.0 * vectors / own.sigma[:, None] ** 2   # dΦ/d(x_i − x_j)
        rows = np.zeros((len(own), k * d + 1))
        for end, sign in ((own.i, 1.0), (own.j, -1.0)):
            held = column[end] >= 0
            for axis in range(d):
                rows[np.flatnonzero(held), column[end][held] + axis] += sign * gradient[held, axis]
        rows[:, -1] = np.einsum("pd,pd->p", gradient,
                                cage_motion[own.i] - cage_motion[own.j]) - 1.0
        # Φ + g·(x − x_k) ≥ 0, x = (δ, t)
        here = np.append(displacements.ravel(), step)
        result = linprog(objective, A_ub=-rows, b_ub=phi - rows @ here, bounds=bounds,
                         method="highs")
        if result.status != 0:
            return None
        previous = step
        displacements, step = result.x[:-1].reshape(k, d), float(result.x[-1])
        if abs(step - previous) <= CAGE_STEP_TOLERANCE * step:
            break
    duals = np.abs(result.ineqlin.marginals)
    binding = np.flatnonzero(duals > BINDING_DUAL * duals.max(initial=0.0))
    # the rattlers that the binding pairs hold (others of the cluster stay free)
    held = np.intersect1d(rattlers, np.concatenate([own.i[binding], own.j[binding]]))
    if binding.size != held.size * d + 1:
        return None
    return CageClosure(held.astype(np.int64), step,
                       displacements[np.searchsorted(rattlers, held)],
                       own.i[binding].astype(np.int64), own.j[binding].astype(np.int64))
