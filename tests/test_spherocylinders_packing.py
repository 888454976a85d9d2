"""`SpherocylinderPacking`: validation, volume formula, φ, nematic order."""

from __future__ import annotations

import math

import numpy as np
import pytest

from generators.spherocylinders import (SpherocylinderPacking, min_particles_for_box,
                                        spherocylinder_volume)


def _random_axes(n, rng):
    axes = rng.normal(size=(n, 3))
    return axes / np.linalg.norm(axes, axis=1)[:, None]


def test_volume_formula():
    # Sphere, and a capsule = sphere + cylinder pi r^2 l.
    assert spherocylinder_volume(2.0, 0.0) == pytest.approx(4 / 3 * math.pi)
    d, l = 0.8, 3.2
    assert spherocylinder_volume(d, l) == pytest.approx(
        4 / 3 * math.pi * (d / 2) ** 3 + math.pi * (d / 2) ** 2 * l)
    gamma = l / d
    assert spherocylinder_volume(d, l) == pytest.approx(math.pi * d**3 / 6 * (1.5 * gamma + 1))


def test_phi_and_properties():
    rng = np.random.default_rng(0)
    n, box = 10, [20.0, 21.0, 22.0]
    diameters = rng.uniform(0.5, 1.5, n)
    lengths = rng.uniform(0.0, 4.0, n)
    packing = SpherocylinderPacking(rng.uniform(0, 20, (n, 3)), _random_axes(n, rng), diameters,
                                    lengths, box)
    expected = np.sum(math.pi * diameters**3 / 6 * (1.5 * lengths / diameters + 1)) / np.prod(box)
    assert packing.phi == pytest.approx(expected, rel=1e-14)
    assert packing.n == n and packing.d == 3
    np.testing.assert_allclose(packing.aspect_ratios, lengths / diameters)
    assert packing.scaled(1.1).phi == pytest.approx(1.1**3 * packing.phi, rel=1e-13)
    wrapped = packing.wrapped()
    assert np.all((wrapped.positions >= 0) & (wrapped.positions < wrapped.box))
    with pytest.raises(ValueError, match="frozen|cannot assign|read-only"):
        packing.positions[0, 0] = 1.0


def test_nematic_order_limits():
    n = 50
    aligned = SpherocylinderPacking(np.zeros((n, 3)), np.tile([0, 0, 1.0], (n, 1)),
                                    np.ones(n), np.full(n, 3.0), 20.0)
    assert aligned.nematic_order() == pytest.approx(1.0, abs=1e-14)
    assert abs(abs(aligned.director()[2]) - 1) < 1e-12
    # Half along x, half along -x and a sign flip change nothing (u and -u are equivalent).
    flipped = SpherocylinderPacking(np.zeros((n, 3)), np.tile([0, 0, 1.0], (n, 1)) *
                                    np.where(np.arange(n) % 2, 1, -1)[:, None], np.ones(n),
                                    np.full(n, 3.0), 20.0)
    assert flipped.nematic_order() == pytest.approx(1.0, abs=1e-14)
    # Axes spread evenly in a plane: Q has eigenvalues (1/4, 1/4, -1/2); S = 1/4.
    angles = np.linspace(0, np.pi, n, endpoint=False)
    planar = np.column_stack([np.cos(angles), np.sin(angles), np.zeros(n)])
    planar_packing = SpherocylinderPacking(np.zeros((n, 3)), planar, np.ones(n), np.ones(n), 20.0)
    assert planar_packing.nematic_order() == pytest.approx(0.25, abs=1e-12)
    # Isotropic: S ~ 1/sqrt(N), and Q traceless.
    rng = np.random.default_rng(1)
    m = 20000
    iso = SpherocylinderPacking(np.zeros((m, 3)), _random_axes(m, rng), np.ones(m), np.ones(m),
                                20.0)
    assert 0 < iso.nematic_order() < 0.03
    assert np.trace(iso.order_tensor()) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("change, message", [
    (dict(positions=np.zeros((2, 2))), "3-dimensional"),
    (dict(axes=[[0, 0, 1], [0, 0, 2]]), "unit vectors"),
    (dict(diameters=[1.0, 0.0]), "diameters must be > 0"),
    (dict(lengths=[1.0, -0.5]), "lengths must be >= 0"),
    (dict(lengths=[1.0]), "lengths has 1 entries"),
    (dict(box=[10.0, 10.0, -1.0]), "box sides must be > 0"),
    (dict(box=5.0), "box too small"),
    (dict(positions=[[0, 0, np.nan], [1, 1, 1]]), "non-finite"),
])
def test_validation(change, message):
    arguments = dict(positions=[[0, 0, 0], [1, 1, 1]], axes=[[0, 0, 1], [0, 1, 0]],
                     diameters=[1.0, 1.0], lengths=[2.0, 2.0], box=10.0)
    arguments.update(change)
    with pytest.raises(ValueError, match=message):
        SpherocylinderPacking(**arguments)


def test_min_particles_for_box():
    # The box rule: (gamma + 1) d < L / 2 with L^3 = N V / eta.
    for gamma, eta in [(0.0, 0.7), (0.4, 0.8), (10.0, 0.5), (20.0, 0.27)]:
        n = min_particles_for_box(gamma, eta)
        for count, fits in [(n, True), (n - 1, False)]:
            side = (count * math.pi / 6 * (1.5 * gamma + 1) / eta) ** (1 / 3)
            assert ((gamma + 1) < side / 2) == fits
