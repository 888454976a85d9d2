"""Force-biased generation: density reached, no overlap (independent KD-tree check),
determinism, errors."""

from __future__ import annotations

import numpy as np
import pytest

import generators
from calippso.geometry.neighbors import close_pairs, min_gap
from generators import diameters as dist


def test_fb_monodisperse_3d_reaches_058_without_overlap():
    diameters = dist.monodisperse(1000)
    result = generators.force_biased(diameters, 3, contraction_rate=1e-3, seed=0)
    packing = result.packing
    gap, overlapping = min_gap(packing.positions, packing.diameters, packing.box)
    assert overlapping == 0 and gap >= -1e-12
    # The closest pair sets the final (inner) size: it touches.
    assert len(close_pairs(packing.positions, packing.diameters, packing.box, 1e-9)) >= 1
    assert packing.phi >= 0.58
    np.testing.assert_allclose(packing.diameters, diameters)
    assert "met" in result.status and np.isnan(result.reduced_pressure)
    assert result.history["phi"][-1] == pytest.approx(packing.phi, rel=1e-9)


def test_fb_slower_contraction_is_denser_and_polydisperse_works():
    diameters = dist.lognormal(500, 0.2, seed=1)
    fast = generators.force_biased(diameters, 3, contraction_rate=1e-2, seed=1)
    slow = generators.force_biased(diameters, 3, contraction_rate=1e-4, seed=1)
    assert slow.packing.phi > fast.packing.phi + 0.05
    assert 0.6 < slow.packing.phi < 0.68
    for result in (fast, slow):
        gap, overlapping = min_gap(result.packing.positions, result.packing.diameters,
                                   result.packing.box)
        assert overlapping == 0


@pytest.mark.parametrize("d, n, low", [(2, 400, 0.72), (4, 400, 0.38), (5, 400, 0.24)])
def test_fb_other_dimensions(d, n, low):
    result = generators.force_biased(dist.monodisperse(n), d, seed=2)
    _, overlapping = min_gap(result.packing.positions, result.packing.diameters,
                             result.packing.box)
    assert overlapping == 0 and result.packing.phi > low and result.packing.d == d


def test_fb_is_deterministic():
    a, b = (generators.force_biased(dist.monodisperse(300), 3, seed=5) for _ in range(2))
    np.testing.assert_array_equal(a.packing.positions, b.packing.positions)


@pytest.mark.parametrize("kwargs, message", [
    (dict(diameters=np.array([1.0, 0.0]), d=3), "diameters"),
    (dict(diameters=np.ones(100), d=1), "dimension"),
    (dict(diameters=np.ones(100), d=3, phi_nominal=1.2), "phi_nominal"),
    (dict(diameters=np.ones(100), d=3, contraction_rate=0), "contraction_rate"),
])
def test_fb_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        generators.force_biased(**kwargs)
