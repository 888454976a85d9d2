"""The pair list of `calippso.geometry.neighbors`: a search given the pairs of a nearby
configuration finds exactly the pairs that a new tree finds."""

from __future__ import annotations

import numpy as np
import pytest

from calippso.geometry.neighbors import NeighborSearch, Pairs

#: Spheres in a periodic cube, at about the density of a random packing.
N_SPHERES = 400
SIDE = 6.5
#: The list reaches this far (diameters), its queries up to `QUERY`.
LISTED = 1.1
QUERY = 1.05


def same_pairs(found: Pairs, expected: Pairs) -> None:
    np.testing.assert_array_equal(found.i, expected.i)
    np.testing.assert_array_equal(found.j, expected.j)
    np.testing.assert_allclose(found.distances, expected.distances, rtol=0, atol=1e-15)


@pytest.mark.parametrize("dimension", [2, 3])
@pytest.mark.parametrize("step", [0.0, 1e-6, 1e-3, 0.02])
def test_a_listed_search_finds_what_a_tree_finds(dimension, step):
    """Moved by `step` per particle (in random directions, across the periodic faces too),
    the search with the list of the old configuration answers every query the list can
    serve, and those beyond it by the tree: the same pairs, in the same order."""
    rng = np.random.default_rng(dimension)
    side = SIDE if dimension == 3 else 18.0
    box = np.full(dimension, side)
    before = rng.uniform(0.0, side, (N_SPHERES, dimension))
    diameters = np.ones(N_SPHERES)
    listed = NeighborSearch(before, diameters, box).pair_list(LISTED)
    direction = rng.standard_normal((N_SPHERES, dimension))
    after = before + step * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    search = NeighborSearch(after, diameters, box, pair_list=listed)
    fresh = NeighborSearch(after, diameters, box)
    assert search.listed_reach() == pytest.approx(LISTED - 2.0 * step, abs=1e-12)
    for cutoff in (1.0, QUERY, 1.3):
        same_pairs(search.pairs_within(cutoff), fresh.pairs_within(cutoff))
    same_pairs(search.pairs_near_contact(), fresh.pairs_near_contact())


def test_a_search_without_a_list_reaches_nothing_listed():
    search = NeighborSearch(np.zeros((2, 3)), np.ones(2), np.full(3, 5.0))
    assert search.listed_reach() == 0.0
