"""Validation against Bargiel (2008) at N = 2000 (slow: run with ``pytest -m slow``)."""

from __future__ import annotations

import pytest

from generators.spherocylinders import force_biased, min_distance_ratio

pytestmark = pytest.mark.slow

N = 2000


@pytest.fixture(scope="module")
def short_rods():
    return {gamma: force_biased(N, gamma, contraction_rate=1e-4, seed=0).packing
            for gamma in (0.0, 0.4, 1.0)}


def test_no_overlap_exact_distance(short_rods):
    for packing in short_rods.values():
        assert min_distance_ratio(packing) >= 1.0


def test_density_maximum_near_short_rods(short_rods):
    phi = {gamma: packing.phi for gamma, packing in short_rods.items()}
    assert 0.62 < phi[0.0] < 0.66  # spheres: random close packing, ≈ 0.64
    assert phi[0.4] > phi[0.0] + 0.02  # the density rises with elongation …
    assert phi[0.4] > phi[1.0]  # … to a maximum near γ ≈ 0.4, then falls


def test_isotropic_without_rotations():
    packing = force_biased(N, 2.0, eps_rot=0.0, contraction_rate=1e-4, seed=0).packing
    assert packing.nematic_order() < 0.05
    assert min_distance_ratio(packing) >= 1.0


@pytest.mark.xfail(reason="measured φ γ ≈ 3.5 (τ = 1e-4) to 3.8 (τ = 3e-5, N = 1000): below "
                          "Bargiel's 4.5 ± 15 % at the contraction rates affordable here",
                   strict=False)
def test_long_rods_follow_phi_gamma_constant():
    gamma = 10.0
    packing = force_biased(N, gamma, contraction_rate=3e-5, seed=0).packing
    assert min_distance_ratio(packing) >= 1.0
    assert packing.phi * gamma == pytest.approx(4.5, rel=0.15)
