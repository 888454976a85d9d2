"""The LP restricted to candidate pairs (`calippso.certification.restricted_lp`): which contacts stay closed."""

from __future__ import annotations

import numpy as np
import pytest
from configurations import random_sequential_addition

from calippso import jam
from calippso.geometry.neighbors import NeighborSearch
from calippso.certification.restricted_lp import MAX_OPEN_CONTACTS, TOO_FEW, TOO_MANY, lp_network


@pytest.fixture(scope="module")
def near_jammed():
    """A jammed packing (LP path), shrunk by 1e-7: its contacts at gaps ~1e-7, the other pairs
    farther; with the neighbour search of the shrunk configuration."""
    result = jam(random_sequential_addition(96, 3, 0.3, seed=21), network_first="off")
    packing = result.packing
    search = NeighborSearch(packing.positions, packing.diameters * (1 - 1e-7), packing.box)
    return result, search


def test_the_jammed_contacts_stay_closed_and_near_pairs_open(near_jammed):
    result, search = near_jammed
    n = result.packing.n
    close = search.pairs_within(float(search.diameters.max()) * 1.05)
    keys = close.i * n + close.j
    contact_keys = result.contacts[:, 0] * n + result.contacts[:, 1]
    stable = ~result.rattlers[close.i] & ~result.rattlers[close.j]
    outside = np.flatnonzero(~np.isin(keys, contact_keys) & stable)
    extra = outside[np.argsort(close.gaps[outside])[:5]]
    candidates = close.subset(np.concatenate([np.flatnonzero(np.isin(keys, contact_keys)),
                                              extra]))
    closed, failure = lp_network(candidates, n, 3)
    assert failure == "" and closed is not None
    chosen = np.sort(candidates.i[closed] * n + candidates.j[closed])
    np.testing.assert_array_equal(chosen, np.sort(contact_keys))


def test_a_hypostatic_candidate_holds_no_self_stress(near_jammed):
    result, search = near_jammed
    i, j = result.contacts[1:].T          # one contact short
    closed, failure = lp_network(search.pairs_of(i, j), result.packing.n, 3)
    assert closed is None and failure == TOO_FEW


def test_a_far_too_hyperstatic_candidate_is_refused(near_jammed):
    result, search = near_jammed
    everything = search.pairs_within(float(search.diameters.max()) * 1.6)
    assert len(everything) - 3 * result.packing.n > MAX_OPEN_CONTACTS
    closed, failure = lp_network(everything, result.packing.n, 3)
    assert closed is None and failure == TOO_MANY
