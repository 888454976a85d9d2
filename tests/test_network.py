"""`calippso.geometry.contact_network`: the finishing stage's functions return new values and their notes."""

from __future__ import annotations

import numpy as np

from calippso.geometry.neighbors import NeighborSearch
from calippso.geometry.contact_network import ROUNDOFF_SHRINK_MARGIN, remove_roundoff_overlaps

BOX = np.full(3, 10.0)


def _pair(separation: float) -> NeighborSearch:
    positions = np.array([[1.0, 1.0, 1.0], [1.0 + separation, 1.0, 1.0], [6.0, 6.0, 6.0]])
    return NeighborSearch(positions, np.ones(3), BOX)


def test_a_roundoff_overlap_is_shrunk_away():
    search = _pair(1.0 - 1e-15)
    shrink = remove_roundoff_overlaps(search)
    assert shrink is not None and 0 < 1 - shrink.factor < 1e-14
    assert 0 <= shrink.min_gap <= 2 * ROUNDOFF_SHRINK_MARGIN
    np.testing.assert_array_equal(shrink.search.diameters, search.diameters * shrink.factor)
    assert shrink.note.startswith("diameters scaled by 1 - ")
    np.testing.assert_array_equal(search.diameters, np.ones(3))   # the input is unchanged


def test_touching_pairs_without_overlap_are_left_alone():
    assert remove_roundoff_overlaps(_pair(1.0)) is None
    assert remove_roundoff_overlaps(_pair(3.0)) is None
