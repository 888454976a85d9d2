"""`calippso.geometry.neighbors.contact_shrink`: the one shrink that takes an overlapping start to
contact, used by LS (`generators.ls`) and by the ensembles' random protocol."""

from __future__ import annotations

import numpy as np
import pytest

from calippso.geometry.neighbors import CONTACT_MARGIN, contact_shrink, min_gap

BOX = np.full(3, 10.0)
DIAMETERS = np.ones(3)


def test_overlapping_start_shrinks_to_the_margin():
    positions = np.array([[1.0, 1.0, 1.0], [1.5, 1.0, 1.0], [5.0, 5.0, 5.0]])
    shrink = contact_shrink(positions, DIAMETERS, BOX)
    assert shrink == pytest.approx(0.5 * (1.0 - CONTACT_MARGIN), rel=1e-15)
    assert min_gap(positions, DIAMETERS * shrink, BOX) == (float("inf"), 0)
    assert 0.5 / shrink - 1.0 == pytest.approx(CONTACT_MARGIN, rel=1e-6)  # the closest pair


def test_overlap_across_the_boundary_counts():
    positions = np.array([[0.2, 1.0, 1.0], [9.9, 1.0, 1.0], [5.0, 5.0, 5.0]])
    assert contact_shrink(positions, DIAMETERS, BOX) == pytest.approx(0.3, rel=1e-8)


@pytest.mark.parametrize("separation", [1.0 + 1e-6, 3.0])
def test_separated_start_is_kept(separation):
    positions = np.array([[1.0, 1.0, 1.0], [1.0 + separation, 1.0, 1.0], [6.0, 6.0, 6.0]])
    assert contact_shrink(positions, DIAMETERS, BOX) == 1.0


def test_ls_start_shrink_is_the_shared_one():
    generators = pytest.importorskip("generators")
    start = generators.poisson(np.ones(64), 3, phi=0.3, seed=4)
    run = generators.lubachevsky_stillinger(start=start, target_pressure=10.0, seed=0)
    assert run.extra["start_shrink"] == contact_shrink(start.positions, start.diameters,
                                                        start.box)
