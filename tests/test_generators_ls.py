"""Lubachevsky–Stillinger compression: target pressure, no overlap (independent KD-tree check),
typical densities, the slow end, input errors (determinism: tests/test_determinism.py; import
hygiene: tests/test_imports.py)."""

from __future__ import annotations

import numpy as np
import pytest

import generators
from calippso import Packing
from calippso.geometry.neighbors import min_gap
from generators import diameters as dist

#: Largest overlap tolerated, relative to σ_ij (round-off only).
OVERLAP_TOL = 1e-12


def assert_no_overlap(packing: Packing) -> None:
    gap, overlapping = min_gap(packing.positions, packing.diameters, packing.box)
    assert gap >= -OVERLAP_TOL, f"{overlapping} overlapping pair(s), min gap {gap:.3g} σ"


@pytest.mark.parametrize("d, n, make, phi_range", [
    (2, 256, lambda n: dist.bidisperse(n, 1.4, 0.5, seed=3), (0.80, 0.86)),
    (3, 256, dist.monodisperse, (0.62, 0.66)),
    (4, 128, dist.monodisperse, (0.43, 0.49)),
    (5, 128, dist.monodisperse, (0.28, 0.34)),
])
def test_ls_reaches_target_pressure_without_overlap(d, n, make, phi_range):
    diameters = make(n)
    result = generators.lubachevsky_stillinger(diameters, d=d, target_pressure=1e5, seed=1)
    packing = result.packing
    assert result.reduced_pressure >= 1e5
    assert packing.d == d and packing.n == n
    np.testing.assert_allclose(np.sort(packing.diameters), np.sort(diameters), rtol=1e-12)
    assert_no_overlap(packing)
    assert phi_range[0] < packing.phi < phi_range[1]
    assert result.extra["overlap_correction"] < 1e-12
    history = result.history
    assert history["pressure"][-1] == result.reduced_pressure
    assert np.all(np.diff(history["phi"]) >= 0) and np.all(np.diff(history["time"]) > 0)


def test_ls_from_packing_keeps_box_and_grows():
    start = generators.poisson(dist.lognormal(100, 0.2, seed=2), 3, phi=0.3, seed=2)
    result = generators.lubachevsky_stillinger(start=start, target_pressure=1e3, seed=2)
    np.testing.assert_array_equal(result.packing.box, start.box)
    ratio = result.packing.diameters / start.diameters
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)  # growth ∝ nominal diameters
    assert result.extra["start_shrink"] < 1  # the Poisson start overlapped
    assert result.reduced_pressure >= 1e3 and result.packing.phi > 0.55
    assert_no_overlap(result.packing)


def test_ls_max_collisions_stops_early():
    result = generators.lubachevsky_stillinger(dist.monodisperse(128), d=3, max_collisions=1000)
    assert result.steps == 1000 and "max_collisions" in result.status


def test_ls_slow_end_switches_rate_once_and_keeps_it():
    result = generators.lubachevsky_stillinger(dist.monodisperse(64), d=3, target_pressure=1e3,
                                               seed=3, final_growth_rate=1e-3,
                                               slowdown_pressure=1e2)
    history = result.history
    slow = history["rate"] == 1e-3
    first = int(np.argmax(slow))
    assert history["pressure"][first - 1] >= 1e2 > history["pressure"][first - 2]
    assert np.all(slow[first:]) and not np.any(slow[:first])
    assert result.reduced_pressure >= 1e3
    assert_no_overlap(result.packing)


def test_ls_slow_end_stops_at_a_jamming_point():
    """With a slow end, the LS state is jammed up to the free-volume law: the exact jamming
    density lies above it by φ_J/φ − 1 = d/p (to 10 %), and the LP loop barely moves it
    (docs/howto/start-configurations.md, "A slow end")."""
    import calippso

    ls = generators.lubachevsky_stillinger(dist.monodisperse(128), d=3, target_pressure=1e6,
                                           seed=2, final_growth_rate=1e-3)
    jammed = calippso.jam(ls.packing)
    assert jammed.converged and jammed.isostatic
    excess = jammed.phi / ls.packing.phi - 1
    assert excess == pytest.approx(3 / ls.reduced_pressure, rel=0.1)
    assert jammed.iterations <= 4


@pytest.mark.parametrize("call, message", [
    (lambda: generators.lubachevsky_stillinger(np.ones(64), d=3, final_growth_rate=0.1),
     "final_growth_rate 0.1 exceeds growth_rate 0.01"),
    (lambda: generators.lubachevsky_stillinger(np.ones(64), d=3, final_growth_rate=-1),
     "final_growth_rate must be"),
    (lambda: generators.lubachevsky_stillinger(np.ones(64), d=3, slowdown_pressure=0),
     "slowdown_pressure must be"),
    (lambda: generators.lubachevsky_stillinger(np.array([1.0, -1.0, 1.0]), d=3), "diameters"),
    (lambda: generators.lubachevsky_stillinger(np.ones(10), d=1), "dimension"),
    (lambda: generators.lubachevsky_stillinger(np.ones(10)), "dimension"),
    (lambda: generators.lubachevsky_stillinger(np.ones(64), d=3, growth_rate=0), "growth_rate"),
    (lambda: generators.lubachevsky_stillinger(np.ones(64), d=3, temperature=-1), "temperature"),
    (lambda: generators.poisson(np.ones(64), 3, phi=1.5), "phi"),
    (lambda: generators.poisson(np.ones(4), 3, phi=0.5), "too few particles"),
    (lambda: dist.lognormal(10, -0.1), "std"),
    (lambda: dist.bidisperse(10, 0.5), "ratio"),
])
def test_bad_input_raises_clear_value_error(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_diameter_distributions():
    sample = dist.lognormal(200_000, 0.2, seed=1)
    assert sample.mean() == pytest.approx(1.0, abs=1e-12)
    assert sample.std() == pytest.approx(0.2, rel=0.02)
    np.testing.assert_array_equal(dist.lognormal(50, 0.1, seed=4), dist.lognormal(50, 0.1, seed=4))
    binary = dist.bidisperse(101, 1.4, 0.3, seed=0)
    assert np.count_nonzero(binary == 1.4) == 30 and np.count_nonzero(binary == 1.0) == 71
    np.testing.assert_array_equal(dist.monodisperse(5), np.ones(5))
    packing = generators.poisson(dist.monodisperse(300), 4, phi=0.2, seed=0)
    assert packing.phi == pytest.approx(0.2) and packing.d == 4
