"""Gaps h_ij = |r_ij|/σ_ij − 1 between stable particles that are not in contact."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..geometry.neighbors import NeighborSearch
from ..result import JammingResult
from ..geometry.touching import TOUCHING_GAP
from ._inputs import as_results
from .sample import PooledSample

__all__ = ["DEFAULT_MAX_GAP", "TOUCHING", "gaps", "pooled_gaps"]

#: Largest gap h kept by default (pairs with |r_ij| ≤ 1.1 σ_ij).
DEFAULT_MAX_GAP = 0.1
#: Pairs with h at most this touch to round-off: a touching pair outside the network (zero
#: force, `JammingResult.touching`) is neither a contact nor a gap, and is left out.
TOUCHING = TOUCHING_GAP


def gaps(result: JammingResult, max_gap: float = DEFAULT_MAX_GAP) -> np.ndarray:
    """Gaps between pairs of stable particles that are not in contact, up to `max_gap`.

    Parameters
    ----------
    result : JammingResult
    max_gap : float
        Largest relative gap h = |r_ij|/σ_ij − 1 kept (> 0, dimensionless). The pair search
        reaches (1 + max_gap) × the largest diameter, which must stay below half the box.

    Returns
    -------
    ndarray, shape (K,)
        Gaps h_ij of every non-contact pair (i, j) of stable particles with
        `TOUCHING` < h_ij ≤ max_gap, ascending. Contacts (the pairs in `result.contacts`) are
        never included, nor are touching pairs that carry no force (h_ij ≤ `TOUCHING`).
    """
    if not max_gap > 0:
        raise ValueError(f"max_gap must be positive, got {max_gap!r}")
    packing = result.packing
    search = NeighborSearch(packing.positions, packing.diameters, packing.box,
                            packing.periodic)
    pairs = search.pairs_within((1.0 + max_gap) * float(np.max(packing.diameters)))
    stable = ~result.rattlers
    keys = pairs.i * packing.n + pairs.j
    contact_keys = result.contacts[:, 0] * packing.n + result.contacts[:, 1]
    h = pairs.gaps
    keep = (stable[pairs.i] & stable[pairs.j] & ~np.isin(keys, contact_keys)
            & (h > TOUCHING) & (h <= max_gap))
    return np.sort(h[keep])


def pooled_gaps(results: JammingResult | Iterable[JammingResult],
                max_gap: float = DEFAULT_MAX_GAP) -> PooledSample:
    """Gaps of every packing, pooled; the cumulative is Z(h) − z per stable particle.

    Parameters
    ----------
    results : JammingResult or iterable of JammingResult
    max_gap : float
        See `gaps`.

    Returns
    -------
    PooledSample
        Normalised by N_s / 2 per packing, so that C(h) = 2 #{pairs with h_ij ≤ h} / N_s is
        the mean number of non-contact neighbours within gap h of a stable particle.
    """
    return PooledSample.concatenate([(gaps(r, max_gap), 0.5 * r.n_stable)
                                     for r in as_results(results)])
