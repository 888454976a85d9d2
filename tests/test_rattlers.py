"""`calippso.geometry.rattlers`: which particles are rattlers (`remove_rattlers`), and rattlers moved
out of overlaps with nothing else moved (`separate_rattlers`)."""

from __future__ import annotations

import numpy as np

from calippso.geometry.neighbors import NeighborSearch
from calippso.geometry.rattlers import RATTLER_CLEARANCE, remove_rattlers, separate_rattlers

from lattices import triangular

CAGED = 5   # a disc of the crystal whose diameter is changed to make it a rattler


def _caged_rattler(diameter: float, shift: float):
    crystal = triangular(4)
    positions = crystal.positions.copy()
    diameters = crystal.diameters.copy()
    diameters[CAGED] = diameter
    positions[CAGED, 0] += shift
    rattlers = np.zeros(crystal.n, dtype=bool)
    rattlers[CAGED] = True
    return positions, diameters, crystal.box, rattlers


def _min_gap(positions, diameters, box) -> float:
    search = NeighborSearch(positions, diameters, box)
    return float(search.pairs_within(float(diameters.max()) * 1.01).gaps.min())


def test_overlapping_rattler_is_moved_into_its_cage():
    positions, diameters, box, rattlers = _caged_rattler(0.95, shift=0.06)
    assert _min_gap(positions, diameters, box) < -0.01
    separated = separate_rattlers(positions, diameters, box, rattlers, reach=0.1)
    assert separated is not None
    np.testing.assert_array_equal(separated[~rattlers], positions[~rattlers])
    # the cage leaves room: every pair with the rattler ends at least the clearance apart
    gaps = NeighborSearch(separated, diameters, box).pairs_within(1.01)
    with_rattler = rattlers[gaps.i] | rattlers[gaps.j]
    assert gaps.gaps[with_rattler].min() >= RATTLER_CLEARANCE * (1 - 1e-3)
    assert _min_gap(separated, diameters, box) >= -1e-14   # the crystal's own contacts


def test_rattler_too_large_for_its_cage_is_reported():
    positions, diameters, box, rattlers = _caged_rattler(1.001, shift=0.0)
    assert separate_rattlers(positions, diameters, box, rattlers, reach=0.1) is None


def test_no_rattler_leaves_positions_unchanged():
    positions, diameters, box, _ = _caged_rattler(1.0, shift=0.0)
    none = np.zeros(len(diameters), dtype=bool)
    assert separate_rattlers(positions, diameters, box, none) is positions


def test_rattlers_are_removed_recursively():
    # d = 2: a complete graph on 0-3 and particle 4 on three of them are stable; 5, 7 and 8
    # have two contacts each, and once they go, 6 (three contacts at first) is left with none
    pairs = np.array([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3), (0, 4), (1, 4), (2, 4),
                      (3, 5), (4, 5), (5, 6), (6, 7), (6, 8), (7, 8)])
    rattlers, kept = remove_rattlers(9, 2, pairs[:, 0], pairs[:, 1])
    np.testing.assert_array_equal(np.flatnonzero(rattlers), [5, 6, 7, 8])
    np.testing.assert_array_equal(kept, np.arange(len(pairs)) < 9)
