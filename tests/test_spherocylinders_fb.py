"""Force-biased spherocylinder packings: no overlaps (exact distance), φ, S, mixtures, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from generators.result import GenerationResult
from generators.spherocylinders import (SpherocylinderPacking, default_initial_density,
                                        force_biased, min_distance_ratio,
                                        min_particles_for_box, rigid_body_eps_rot,
                                        spherocylinder_volume)
from generators.spherocylinders import fb as fb_module
from generators.spherocylinders.fb import INITIAL_DENSITY, start_density
from generators.spherocylinders.cells import pair_list
from generators.spherocylinders.geometry import shaft_distance


@pytest.fixture(scope="module")
def runs():
    """A few fast N = 200 runs shared by the tests (compile time included once)."""
    return {gamma: force_biased(200, gamma, contraction_rate=1e-3, seed=1)
            for gamma in (0.0, 0.4, 2.0)}


@pytest.mark.parametrize("gamma", [0.0, 0.4, 2.0])
def test_final_packing_has_no_overlap(runs, gamma):
    result = runs[gamma]
    assert isinstance(result, GenerationResult)
    packing = result.packing
    assert isinstance(packing, SpherocylinderPacking)
    assert packing.n == 200
    np.testing.assert_allclose(packing.aspect_ratios, gamma, atol=1e-12)
    # Exact shaft distance over all pairs: no overlap, and the packing is jammed-ish (touching).
    ratio = min_distance_ratio(packing)
    assert 1.0 <= ratio < 1.0 + 1e-6
    assert "densification" in result.status


def test_density_is_reasonable(runs):
    phi = {gamma: runs[gamma].packing.phi for gamma in runs}
    # Fast compressions of 200 particles: loose but clearly dense random packings.
    assert 0.57 < phi[0.0] < 0.66
    assert phi[0.4] > phi[0.0]  # short rods pack better than spheres
    assert 0.45 < phi[2.0] < 0.70


def test_phi_matches_the_volume_formula(runs):
    packing = runs[2.0].packing
    d, l = packing.diameters, packing.lengths
    expected = np.sum(math.pi * d**3 / 6 * (1.5 * l / d + 1)) / packing.box.prod()
    assert packing.phi == pytest.approx(expected, rel=1e-14)
    # Every particle has the volume of a unit-diameter sphere times the final scale cubed.
    volumes = spherocylinder_volume(d, l)
    np.testing.assert_allclose(volumes, volumes[0], rtol=1e-12)


def test_history_and_extra(runs):
    result = runs[0.4]
    history = result.history
    assert history.dtype.names == ("time", "phi", "pressure", "rate")
    assert len(history) > 2 and np.all(np.diff(history["time"]) >= 0)
    assert history["phi"].max() <= result.packing.phi * (1 + 1e-9)
    assert result.steps == int(history["time"][-1])
    assert result.extra["meetings"] >= 1
    assert result.extra["phi_nominal"] >= result.packing.phi * (1 - 1e-9)
    assert math.isnan(result.reduced_pressure)


def test_fixed_orientations_with_eps_rot_zero():
    n, seed = 200, 4
    result = force_biased(n, 1.0, eps_rot=0.0, contraction_rate=1e-3, seed=seed)
    rng = np.random.default_rng(seed)
    rng.uniform(size=(n, 3))
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    np.testing.assert_allclose(result.packing.axes, axes, atol=1e-14)
    # Isotropic: S of N random axes is ~ 1/sqrt(N) (about 0.06 at N = 200).
    assert result.packing.nematic_order() < 0.15
    turned = force_biased(n, 1.0, eps_rot=0.5, contraction_rate=1e-3, seed=seed)
    assert np.max(np.abs(np.abs(np.sum(turned.packing.axes * axes, axis=1)) - 1)) > 1e-3
    assert min_distance_ratio(turned.packing) >= 1.0


def test_same_seed_same_packing():
    first = force_biased(100, 0.5, contraction_rate=3e-3, seed=9)
    second = force_biased(100, 0.5, contraction_rate=3e-3, seed=9)
    np.testing.assert_array_equal(first.packing.positions, second.packing.positions)
    np.testing.assert_array_equal(first.packing.axes, second.packing.axes)


def test_bidisperse_mixture():
    result = force_biased(200, 0.0, mixture=(80, 1.5), contraction_rate=1e-3, seed=2)
    packing = result.packing
    gammas = packing.aspect_ratios
    assert np.count_nonzero(np.isclose(gammas, 1.5)) == 80
    assert np.count_nonzero(np.isclose(gammas, 0.0)) == 120
    volumes = packing.particle_volumes
    np.testing.assert_allclose(volumes, volumes[0], rtol=1e-12)  # equal particle volumes
    assert min_distance_ratio(packing) >= 1.0
    assert "120 × γ = 0 + 80 × γ = 1.5" == result.extra["composition"]


@pytest.mark.parametrize("kwargs, message", [
    (dict(n=200, aspect_ratio=-0.5), "aspect ratios must be finite and >= 0"),
    (dict(n=200, aspect_ratio=5.0), r"use N >= 3\d\d"),
    (dict(n=1, aspect_ratio=0.5), "n must be an integer >= 2"),
    (dict(n=200, aspect_ratio=0.5, mixture=(0, 1.0)), "mixture count"),
    (dict(n=200, aspect_ratio=0.5, mixture=(10, -1.0)), "aspect ratios"),
    (dict(n=200, aspect_ratio=0.5, mixture=5), "mixture must be a pair"),
    (dict(n=200, aspect_ratio=0.5, eps=0.0), "eps must be"),
    (dict(n=200, aspect_ratio=0.5, eps_rot=-1.0), "eps_rot must be"),
    (dict(n=200, aspect_ratio=0.5, contraction_rate=2.0), "contraction_rate must be below 1"),
])
def test_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        force_biased(**kwargs)


def test_box_rule_message_gives_the_needed_n():
    gamma, eta = 5.0, 0.5
    needed = math.floor(48 * (gamma + 1) ** 3 * eta / (math.pi * (1.5 * gamma + 1))) + 1
    with pytest.raises(ValueError, match=f"use N >= {needed}"):
        force_biased(needed - 1, gamma, initial_density=eta)
    with pytest.raises(ValueError, match=f"use N >= {needed}"):  # a mixture: longest species
        force_biased(needed - 1, 0.0, mixture=(10, gamma), initial_density=eta)


def test_default_start_is_dense_unless_the_box_forbids_it(runs):
    # N = 200 allows the full start for spheres and short rods.
    assert runs[0.0].extra["initial_density"] == INITIAL_DENSITY == 1.2
    assert runs[2.0].extra["initial_density"] == INITIAL_DENSITY
    # γ = 3 needs N >= 214 for it: N = 150 starts at the densest start the box allows …
    gamma = 3.0
    assert min_particles_for_box(gamma, INITIAL_DENSITY) == 214
    longest = (gamma + 1) * (1.5 * gamma + 1) ** (-1 / 3)  # l + d at volume π/6
    eta0 = default_initial_density(150, longest, gamma)
    assert eta0 < INITIAL_DENSITY
    assert min_particles_for_box(gamma, eta0) == 150
    result = force_biased(150, gamma, contraction_rate=1e-2, seed=0)
    assert result.extra["initial_density"] == pytest.approx(eta0, rel=1e-12)
    assert min_distance_ratio(result.packing) >= 1.0
    # … and a box too small even for 1.2 × the expected density is refused, naming both N.
    with pytest.raises(ValueError, match=r"use N >= 1\d\d \(N >= 214 for the default start"):
        force_biased(100, gamma)


def test_long_rods_start_at_fixed_eta0_gamma():
    """Beyond γ = 10 the default start is 12/γ: η₀ γ, hence the overlaps per rod at the
    start, stays fixed; the box rule is checked against that start."""
    assert start_density(0.0) == start_density(10.0) == INITIAL_DENSITY
    assert start_density(20.0) == pytest.approx(0.6, rel=1e-15)
    assert start_density(80.0) == pytest.approx(0.15, rel=1e-15)
    gamma = 20.0
    needed = min_particles_for_box(gamma, start_density(gamma))
    assert needed == 2739
    with pytest.raises(ValueError, match=rf"\(N >= {needed} for the default start at 0.6\)"):
        force_biased(1200, gamma)
    longest = (gamma + 1) * (1.5 * gamma + 1) ** (-1 / 3)
    assert default_initial_density(needed, longest, gamma) == pytest.approx(0.6, rel=1e-15)
    assert default_initial_density(2000, longest, gamma) < 0.6   # lowered by the box rule


def test_pair_list_matches_brute_force():
    rng = np.random.default_rng(5)
    # (100, 4, 14): fewer than 3 cells per side, so the list is built over all pairs
    for n, gamma, side in [(150, 1.0, 12.0), (100, 3.0, 20.0), (60, 0.0, 5.0), (100, 4.0, 14.0)]:
        positions = rng.uniform(0, side, (n, 3))
        axes = rng.normal(size=(n, 3))
        axes /= np.linalg.norm(axes, axis=1)[:, None]
        diameters = rng.uniform(0.8, 1.2, n)
        half = 0.5 * gamma * diameters
        box = np.full(3, side)
        skin = 0.3
        listed = {tuple(pair) for pair in pair_list(positions, axes, half, diameters, box, skin)}
        expected = set()
        for i in range(n):
            for j in range(i + 1, n):
                distance = shaft_distance(positions[i], axes[i], 2 * half[i], positions[j],
                                          axes[j], 2 * half[j], box=box)[0]
                if distance < 0.5 * (diameters[i] + diameters[j]) + skin:
                    expected.add((i, j))
        assert listed == expected
        # centres outside the box (whole periods away) give the same list
        shifted = positions + side * rng.integers(-2, 3, (n, 3))
        assert {tuple(pair) for pair in pair_list(shifted, axes, half, diameters, box,
                                                  skin)} == expected


def _gyration_radius2_by_quadrature(gamma, points=200_001):
    """I/m about a diameter of a solid spherocylinder (d = 1, l = γ), by slicing along the axis."""
    half = gamma / 2 + 0.5
    z = np.linspace(-half, half, points)
    beyond = np.clip(np.abs(z) - gamma / 2, 0.0, 0.5)
    rho2 = 0.25 - beyond**2  # squared radius of the cross-section at z
    inertia = np.trapezoid(math.pi * rho2**2 / 4 + z**2 * math.pi * rho2, z)
    return inertia / np.trapezoid(math.pi * rho2, z)


@pytest.mark.parametrize("gamma", [0.0, 0.4, 2.0, 10.0, 80.0])
def test_rigid_body_rotation_step(gamma):
    from generators.spherocylinders.fb import gyration_radius2

    k2 = _gyration_radius2_by_quadrature(gamma)
    assert gyration_radius2(gamma) == pytest.approx(k2, rel=1e-6)
    assert rigid_body_eps_rot(gamma, 0.1) == pytest.approx(0.1 * gamma / k2, rel=1e-6)
    if gamma >= 10:  # slender rod: k² → l²/12, a tip contact turns 3× as far as it translates
        assert rigid_body_eps_rot(gamma, 0.1) * gamma / 12 == pytest.approx(0.1, rel=0.2)


def test_default_rotation_is_the_rigid_body_step():
    n, seed, gamma = 200, 4, 1.0
    default = force_biased(n, gamma, contraction_rate=1e-3, seed=seed)
    explicit = force_biased(n, gamma, eps_rot=float(rigid_body_eps_rot(gamma)),
                            contraction_rate=1e-3, seed=seed)
    np.testing.assert_array_equal(default.packing.axes, explicit.packing.axes)
    assert min_distance_ratio(default.packing) >= 1.0
    with pytest.raises(ValueError, match="eps_rot must be None or"):
        force_biased(n, gamma, eps_rot="fast")


def test_wide_skin_of_all_pairs_lists_changes_nothing(monkeypatch):
    """γ = 5, N = 500: the box holds fewer than 3 cells of one rod reach for the whole run, so
    the lists are built over all pairs; their wider skin saves builds, not a bit of the result."""
    wide = force_biased(500, 5.0, contraction_rate=1e-2, seed=3)
    monkeypatch.setattr(fb_module, "BRUTE_FORCE_SKIN", fb_module.SKIN)
    narrow = force_biased(500, 5.0, contraction_rate=1e-2, seed=3)
    assert wide.extra["list_builds"] < narrow.extra["list_builds"]
    assert np.array_equal(wide.packing.positions, narrow.packing.positions)
    assert np.array_equal(wide.packing.axes, narrow.packing.axes)
