"""Closest-jamming (MLS) protocol: it stops jammed at the pressure threshold, without overlap,
in the expected density range; rate schedule and errors."""

from __future__ import annotations

import numpy as np
import pytest

import generators
from calippso.geometry.neighbors import min_gap
from generators import diameters as dist

from configurations import mls_start


@pytest.fixture(scope="module")
def jammed(mls_jammed):
    """N = 64 in d = 3 from φ = 0.3, to p = 1e9 at a final rate of 1e-3 (conftest.py)."""
    return mls_start(), mls_jammed


def test_mls_jams_without_overlap(jammed):
    start, result = jammed
    assert result.status.startswith("jammed")
    assert result.reduced_pressure > 1e9
    packing = result.packing
    gap, overlapping = min_gap(packing.positions, packing.diameters, packing.box)
    assert overlapping == 0 and gap >= -1e-12
    assert 0.60 < packing.phi < 0.66  # N = 64: wide finite-size range around 0.63–0.64
    np.testing.assert_array_equal(packing.box, start.box)


def test_mls_rate_schedule(jammed):
    _, result = jammed
    rates = result.history["rate"]
    growth = rates[rates > 0]
    assert growth[0] == 10.0 and growth[-1] <= 1e-3 * 1.0000001
    assert np.all(np.diff(growth) <= 0)  # the rate only decreases
    assert np.any(rates == 0)  # equilibration windows happened
    ratios = growth[:-1][np.diff(growth) < 0] / growth[1:][np.diff(growth) < 0]
    assert np.all((ratios > 1.999) & (ratios < 2.001) | (growth[1:][np.diff(growth) < 0] == 1e-3))


def test_mls_max_collisions_and_errors():
    start = generators.poisson(dist.monodisperse(64), 3, phi=0.2, seed=0)
    result = generators.closest_jamming(start=start, max_collisions=5000)
    assert result.steps == 5000 and "max_collisions" in result.status
    with pytest.raises(ValueError, match="final_rate"):
        generators.closest_jamming(start=start, initial_rate=1e-3, final_rate=1e-2)
    with pytest.raises(ValueError, match="rate_decrease"):
        generators.closest_jamming(start=start, rate_decrease=1.0)
    with pytest.raises(ValueError, match="start"):
        generators.closest_jamming(start=np.ones(10))


@pytest.fixture(scope="module")
def levelled_off():
    # a threshold the pressure (almost) never reaches: the rates end after
    # max_windows_per_rate windows, the final one included
    start = generators.poisson(dist.monodisperse(64), 3, phi=0.3, seed=1)
    return generators.closest_jamming(start=start, max_pressure=1e300, final_rate=1e-2,
                                      max_windows_per_rate=3, seed=1)


def test_mls_lowers_the_rate_when_the_pressure_levels_off(levelled_off):
    assert levelled_off.status.startswith("levelled off: p stayed below 1e+300 for 3 windows")
    rates = levelled_off.history["rate"]
    growth = rates[rates > 0]
    values, counts = np.unique(growth, return_counts=True)
    assert counts.max() == 3 and values.max() == 10.0  # at most 3 growth windows per rate
    assert values.min() == 1e-2 and counts[0] == 3 and growth[-1] == 1e-2
    packing = levelled_off.packing
    gap, overlapping = min_gap(packing.positions, packing.diameters, packing.box)
    assert overlapping == 0


def test_mls_levelled_off_run_resumes_as_finished(levelled_off, tmp_path):
    start = generators.poisson(dist.monodisperse(64), 3, phi=0.3, seed=1)
    options = dict(max_pressure=1e300, final_rate=1e-2, max_windows_per_rate=3, seed=1,
                   checkpoint=tmp_path / "mls.npz")
    first = generators.closest_jamming(start=start, **options)
    again = generators.closest_jamming(start=start, **options)
    assert again.status == first.status == levelled_off.status
    assert again.steps == first.steps
    np.testing.assert_array_equal(again.packing.positions, first.packing.positions)


@pytest.mark.parametrize("bad", [0, -5, 2.5, True])
def test_mls_max_windows_per_rate_must_be_a_positive_integer(bad):
    start = generators.poisson(dist.monodisperse(64), 3, phi=0.2, seed=0)
    with pytest.raises(ValueError, match="max_windows_per_rate must be a positive integer"):
        generators.closest_jamming(start=start, max_windows_per_rate=bad)
