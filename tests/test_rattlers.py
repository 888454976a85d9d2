"""`calippso.rattlers.separate_rattlers`: rattlers moved out of overlaps, nothing else moved."""

from __future__ import annotations

import numpy as np

from calippso.neighbors import NeighborSearch
from calippso.rattlers import RATTLER_CLEARANCE, separate_rattlers

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
