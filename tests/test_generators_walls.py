"""Generators between flat hard walls: the soft quench (harmonic walls) and LS (wall
collisions as events). Each walled packing lies inside its container, overlaps nothing, is
not wrapped along its walled axes, and reaches a density that makes sense; the kernels'
wall terms are checked against the energy they derive from."""

from __future__ import annotations

import numpy as np
import pytest

import calippso
import generators
from calippso import Boundaries
from calippso.neighbors import min_gap
from generators import diameters as dist

#: Relative overlap allowed between two particles (round-off), × the diameter.
OVERLAP_TOLERANCE = 1e-9

#: (d, diameters, walled axes) of the walled runs: bidisperse discs (1:1.4, which do not
#: crystallise) and equal spheres, walls on one axis and on two.
CASES = {"d2_x": (2, dist.bidisperse(128, 1.4), ["x"]),
         "d2_xy": (2, dist.bidisperse(128, 1.4), ["x", "y"]),
         "d3_x": (3, dist.monodisperse(128), ["x"]),
         "d3_xy": (3, dist.monodisperse(128), ["x", "y"])}

#: Bands of the jammed-ish density of a quench of N = 128 between walls: below the periodic
#: value (0.84 for these discs, 0.64 for spheres) by the looser layers at the walls.
QUENCH_PHI = {2: (0.76, 0.85), 3: (0.52, 0.64)}


def assert_inside_and_apart(packing, boundaries: Boundaries) -> None:
    """The packing carries `boundaries`, every centre lies between its walls, and no two
    particles overlap (minimum image along the periodic axes only)."""
    assert packing.boundaries == boundaries
    boundaries.check(packing.positions, packing.diameters, packing.box)
    radius = packing.diameters / 2
    for axis in boundaries.wall_axes:
        x = packing.positions[:, axis]
        assert np.all(x >= radius * (1 - 2 * OVERLAP_TOLERANCE))
        assert np.all(x <= packing.box[axis] - radius * (1 - 2 * OVERLAP_TOLERANCE))
    gap, overlapping = min_gap(packing.positions, packing.diameters, packing.box,
                               packing.periodic)
    assert overlapping == 0 or gap >= -OVERLAP_TOLERANCE


def wall_forces(result, d: int) -> np.ndarray:
    """Total harmonic force of each wall of a quench on its particles, shape (2 d,), up to one
    common factor: a wall overlap 1 − δ/(σ/2) = w gives the force w / (2σ) (ε = 1)."""
    particle, wall = result.extra["wall_contacts"].T
    sigma = result.packing.diameters[particle] / result.packing.diameters.mean()
    return np.bincount(wall, weights=result.extra["wall_overlaps"] / (2 * sigma),
                       minlength=2 * d)


# ------------------------------------------------------------------ the kernels


def _two_particles_near_opposite_walls(periodic: np.ndarray):
    """Two unit spheres 0.3 from x = 0 and from x = L = 5: they overlap through the periodic
    image only."""
    x = np.array([[0.3, 2.5, 2.5], [4.7, 2.5, 2.5]])
    return x, np.full(3, 5.0), np.ones(2), periodic


def test_verlet_lists_do_not_wrap_along_a_walled_axis():
    from generators.cells import verlet_lists

    for periodic, listed in ((np.array([True, True, True]), 1),
                             (np.array([False, True, True]), 0)):
        x, box, sigma, mask = _two_particles_near_opposite_walls(periodic)
        start, _ = verlet_lists(x, box, sigma, 0.1, mask)
        assert start[-1] == 2 * listed


def test_verlet_lists_between_walls_find_every_pair_with_two_cells():
    """Two cells along a walled axis: each pair within reach is found whichever cell holds
    its lower index (the cells do not wrap, so both neighbours of a cell are searched)."""
    from generators.cells import verlet_lists

    rng = np.random.default_rng(3)
    x = rng.uniform(0, 1, (60, 2)) * np.array([2.5, 6.0])
    box, sigma = np.array([2.5, 6.0]), np.full(60, 0.5)
    start, neighbours = verlet_lists(x, box, sigma, 0.6, np.array([False, True]))
    found = {(i, j) for i in range(60) for j in neighbours[start[i]:start[i + 1]] if i < j}
    delta = x[:, None, :] - x[None, :, :]
    delta[..., 1] -= 6.0 * np.round(delta[..., 1] / 6.0)
    close = np.sqrt((delta ** 2).sum(-1)) < 1.1
    expected = {(i, j) for i in range(60) for j in range(i + 1, 60) if close[i, j]}
    assert found == expected


def _energy_terms(x, s, scale, box, periodic):
    """Harmonic forces, virial and energy of `_fire.harmonic_forces` for these positions."""
    from generators import _fire
    from generators.cells import verlet_lists

    lists = _fire.pair_lists(*verlet_lists(x, box, scale * s, 0.5, periodic))
    f = np.zeros_like(x)
    pair_force = np.empty((lists[1].shape[0], x.shape[1]))
    sums = _fire.harmonic_forces(x, np.zeros_like(x), s, scale, box, *lists, pair_force, f,
                                 _fire.work_array(x.shape[0]), periodic)
    return f, sums[5], sums[7], sums[6]


def test_harmonic_wall_forces_and_virial_derive_from_the_energy():
    """With walls in x: the force is −∂E/∂x and the virial a ∂E/∂a (the pressure's
    conjugate of the diameter scale) to finite-difference accuracy, and a particle
    overlapping a wall by δ has the energy of a pair overlapping by δ, (δ/σ)²/2."""
    periodic = np.array([False, True, True])
    x = np.array([[0.4, 1.0, 1.0], [1.2, 1.3, 1.1], [2.2, 1.2, 1.0], [3.2, 1.4, 1.0]])
    s = np.array([1.0, 1.0, 1.2, 0.9])
    box = np.full(3, 3.6)
    scale = 1.02
    f, virial, energy, overlaps = _energy_terms(x, s, scale, box, periodic)
    assert overlaps == 5            # pairs 0-1, 1-2, 2-3; particle 0 at x = 0, 3 at x = L
    step = 1e-7
    for i, mu in ((0, 0), (3, 0), (1, 1), (2, 0), (3, 2)):
        moved = [x.copy(), x.copy()]
        moved[0][i, mu] += step
        moved[1][i, mu] -= step
        derivative = (_energy_terms(moved[0], s, scale, box, periodic)[2]
                      - _energy_terms(moved[1], s, scale, box, periodic)[2]) / (2 * step)
        assert f[i, mu] == pytest.approx(-derivative, rel=1e-6, abs=1e-9)
    da = 1e-7
    derivative = (_energy_terms(x, s, scale * np.exp(da), box, periodic)[2]
                  - _energy_terms(x, s, scale * np.exp(-da), box, periodic)[2]) / (2 * da)
    assert virial == pytest.approx(derivative, rel=1e-6)
    alone = np.array([[0.4, 1.0, 1.0]])
    delta = scale / 2 - 0.4
    assert _energy_terms(alone, s[:1], scale, box, periodic)[2] == pytest.approx(
        0.5 * (delta / scale) ** 2, rel=1e-12)


# ------------------------------------------------------------------ the soft quench


@pytest.fixture(scope="module")
def quenches():
    return {name: generators.soft_quench(sizes, d, seed=1,
                                         boundaries=Boundaries.walls(d, axes))
            for name, (d, sizes, axes) in CASES.items()}


@pytest.mark.parametrize("name", list(CASES))
def test_quench_between_walls_is_inside_apart_and_jammed_ish(name, quenches):
    d, sizes, axes = CASES[name]
    walls = Boundaries.walls(d, axes)
    result = quenches[name]
    assert result.status.startswith("converged")
    assert_inside_and_apart(result.packing, walls)
    np.testing.assert_array_equal(result.packing.diameters, sizes)
    low, high = QUENCH_PHI[d]
    assert low < result.packing.phi < high
    assert result.extra["isostaticity_gap"] >= 0     # walls counted, none hypostatic
    # pairs only in `contacts`; the wall contacts are on the walls of the walled axes
    assert result.contacts.shape[1] == 2 and result.contacts.max() < len(sizes)
    forces = wall_forces(result, d)
    for axis in range(d):
        if axis in walls.wall_axes:
            # every wall pushes, and the two walls of an axis balance (the particles are in
            # equilibrium at the end of the quench)
            assert forces[2 * axis] > 0 and forces[2 * axis + 1] > 0
            assert forces[2 * axis] == pytest.approx(forces[2 * axis + 1], rel=1e-3)
        else:
            assert forces[2 * axis] == forces[2 * axis + 1] == 0


def test_walled_axes_are_not_wrapped(quenches):
    """Along a walled axis every centre keeps its side: no particle touches both walls'
    images (the pair network has no pair closer through the periodic image than directly)."""
    result = quenches["d3_x"]
    packing = result.packing
    i, j = result.contacts.T
    delta = packing.positions[i, 0] - packing.positions[j, 0]
    assert np.all(np.abs(delta) < packing.diameters.max())


def test_quench_between_walls_is_certified_by_jam(quenches):
    """The quench is a start next to its jamming point: jam certifies it isostatic, with
    wall contacts, in a few LPs."""
    result = calippso.jam(quenches["d2_x"].packing)
    assert result.isostatic
    assert result.n_wall_contacts > 0
    assert result.iterations <= 5


def test_quench_refuses_a_cylinder():
    with pytest.raises(ValueError, match="soft_quench does not handle cylinder"):
        generators.soft_quench(dist.monodisperse(64), 3,
                               boundaries=Boundaries.cylinder(3, ["x", "y"]))
