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
from calippso.geometry.neighbors import min_gap
from generators import diameters as dist
from generators.periodic import NO_CYLINDER

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
                                 _fire.work_array(x.shape[0]), periodic, NO_CYLINDER)
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
def quenches(computed_once):
    return computed_once("walls_quenches", lambda: {
        name: generators.soft_quench(sizes, d, seed=1, boundaries=Boundaries.walls(d, axes))
        for name, (d, sizes, axes) in CASES.items()})


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


# ------------------------------------------------------------------ Lubachevsky–Stillinger

#: Reduced pressure of the walled LS runs, and the band of their densities (N = 128, a fast
#: growth rate: below the periodic LS values, 0.84 for these discs and 0.64 for spheres).
LS_PRESSURE = 1e5
LS_PHI = {2: (0.76, 0.86), 3: (0.54, 0.65)}


def test_wall_event_meets_the_growing_sphere_and_reflects_with_the_growth():
    """A sphere of radius 1/2 growing at s γ/2 = 0.1, one radius from the wall at 0 and
    moving towards it at speed 1: it touches the wall when x(τ) = σ(τ)/2, and leaves with
    the normal speed 2w − u = 0.2 + 1, as if off a mirror partner growing with it."""
    from generators.edmd import _wall_collision, _wall_event

    x = np.array([[1.0, 2.0]])
    v = np.array([[-1.0, 0.3]])
    s, box, rate = np.array([1.0]), np.array([4.0, 4.0]), 0.2
    tau, wall = _wall_event(0, x, v, s, box, np.array([False, True]), 1.0, rate,
                            NO_CYLINDER)
    assert wall == 0
    assert x[0, 0] + v[0, 0] * tau == pytest.approx(0.5 * s[0] * (1.0 + rate * tau), rel=1e-14)
    scale = 1.0 + rate * tau
    virial = _wall_collision(0, wall, v, s, scale, rate)
    assert v[0, 0] == pytest.approx(1.2, rel=1e-14) and v[0, 1] == 0.3
    assert virial == pytest.approx(0.5 * scale * 2.2, rel=1e-14)
    # the same sphere moving away from the wall and slower than its growth meets the far wall
    v = np.array([[0.05, 0.0]])
    tau, wall = _wall_event(0, x, v, s, box, np.array([False, True]), 1.0, rate,
                            NO_CYLINDER)
    assert wall == 0 and tau == pytest.approx(0.5 / (0.1 - 0.05))
    assert _wall_event(0, x, v, s, box, np.array([True, True]), 1.0, rate,
                       NO_CYLINDER)[0] == np.inf


def test_elastic_walls_conserve_the_kinetic_energy():
    """At zero growth and without velocity rescaling, spheres bouncing between walls (in x
    and y) and off each other keep their kinetic energy, and stay inside."""
    from generators.edmd import run_window

    start = generators.poisson(np.ones(40), 3, phi=0.05, seed=4,
                               boundaries=Boundaries.walls(3, ["x", "y"]))
    x = start.positions.copy()
    v = np.random.default_rng(4).standard_normal(x.shape)
    energy = np.sum(v ** 2)
    periodic = start.periodic.astype(bool)
    # a writable box and the cylinder argument, as the generators pass them: the kernel's
    # compiled variant is reused
    box = np.array(start.box)
    _, _, virial, _, collisions, _ = run_window(x, v, np.ones(40), box, 1.0, 0.0, 1.0,
                                                4000, 10 ** 9, 0.1, np.inf, periodic,
                                                NO_CYLINDER)
    assert collisions == 4000 and virial > 0
    assert np.sum(v ** 2) == pytest.approx(energy, rel=1e-12)
    Boundaries.walls(3, ["x", "y"]).check(x, np.ones(40), start.box)


@pytest.fixture(scope="module")
def ls_runs(computed_once):
    return computed_once("walls_ls_runs", lambda: {
        name: generators.lubachevsky_stillinger(sizes, d, seed=1, target_pressure=LS_PRESSURE,
                                                boundaries=Boundaries.walls(d, axes))
        for name, (d, sizes, axes) in CASES.items()})


@pytest.mark.parametrize("name", list(CASES))
def test_ls_between_walls_reaches_its_pressure_inside_and_apart(name, ls_runs):
    d, sizes, axes = CASES[name]
    walls = Boundaries.walls(d, axes)
    result = ls_runs[name]
    assert result.reduced_pressure >= LS_PRESSURE
    assert_inside_and_apart(result.packing, walls)
    np.testing.assert_allclose(result.packing.diameters, sizes, rtol=1e-14)
    low, high = LS_PHI[d]
    assert low < result.packing.phi < high
    # near jamming the spheres press on every wall: some centres within 1e-3 σ of contact
    radius = result.packing.diameters / 2
    for axis in walls.wall_axes:
        x = result.packing.positions[:, axis]
        assert np.any(x - radius < 1e-3 * radius)
        assert np.any(result.packing.box[axis] - x - radius < 1e-3 * radius)


def test_ls_between_walls_is_certified_by_jam(ls_runs):
    result = calippso.jam(ls_runs["d2_xy"].packing)
    assert result.isostatic
    assert result.n_wall_contacts > 0


def test_ls_continues_a_walled_start_and_keeps_its_walls():
    """A walled start (random sequential addition-like Poisson points, shrunk to no
    overlap) is compressed in its own container; boundaries= contradicting it is refused."""
    walls = Boundaries.walls(2, ["y"])
    start = generators.poisson(dist.bidisperse(64, 1.4), 2, phi=0.2, seed=3, boundaries=walls)
    result = generators.lubachevsky_stillinger(start=start, target_pressure=1e3, seed=2)
    assert result.reduced_pressure >= 1e3
    assert_inside_and_apart(result.packing, walls)
    np.testing.assert_array_equal(result.packing.box, start.box)
    with pytest.raises(ValueError, match="contradict the start's"):
        generators.lubachevsky_stillinger(start=start, boundaries=Boundaries.walls(2, ["x"]))


@pytest.mark.parametrize("d, sizes, axes", [(2, dist.bidisperse(64, 1.4), ["x", "y"]),
                                             (3, dist.monodisperse(64), ["x"])])
def test_mls_between_walls_jams_inside_its_walls(d, sizes, axes):
    """MLS (the closest-jamming protocol) compresses in the walls of its Poisson start, ends
    jammed, and `jam` certifies the result with wall contacts, isostatic under the walled
    count; a start with its own walls is compressed in them."""
    walls = Boundaries.walls(d, axes)
    result = generators.closest_jamming(sizes, d, seed=1, final_rate=1e-2, boundaries=walls)
    assert result.status.startswith("jammed")
    assert_inside_and_apart(result.packing, walls)
    jammed = calippso.jam(result.packing)
    assert_inside_and_apart(jammed.packing, walls)
    assert jammed.isostatic and jammed.isostaticity_gap == 0
    assert jammed.force_balance <= 1e-12 and jammed.n_wall_contacts > 0
    start = generators.poisson(sizes, d, phi=0.3, seed=2, boundaries=walls)
    assert generators.closest_jamming(start=start, final_rate=1e-1).packing.boundaries == walls


# ------------------------------------------------------------------ force-biased

#: Band of the FB densities between walls (N = 128, default contraction): a loose start,
#: below the periodic FB values.
FB_PHI = {2: (0.72, 0.85), 3: (0.48, 0.63)}


def test_fb_wall_push_is_the_push_of_the_mirror_image():
    """A sphere of nominal diameter 1 at δ = 0.3 from the wall at 0 (and far from the wall at
    L) is pushed along +x by σ² (1 − (2δ)²/σ²), the Bezrukov push of its mirror partner at
    2δ, and the inner scale becomes 2δ/s, the scale at which it would touch the wall."""
    from generators.fb import _wall_pushes

    x = np.array([[0.3, 1.0], [1.5, 1.0]])
    force = np.zeros_like(x)
    inner = _wall_pushes(x, np.ones(2), np.array([3.0, 3.0]), np.array([False, True]), 1.0,
                         force, np.inf, NO_CYLINDER)
    assert force[0, 0] == pytest.approx(1.0 - 0.6 ** 2, rel=1e-14)
    assert force[0, 1] == 0.0 and np.all(force[1] == 0.0)
    assert inner == pytest.approx(0.6, rel=1e-14)


@pytest.mark.parametrize("name", list(CASES))
def test_fb_between_walls_is_inside_and_apart(name):
    d, sizes, axes = CASES[name]
    walls = Boundaries.walls(d, axes)
    result = generators.force_biased(sizes, d, seed=1, boundaries=walls)
    assert result.status.startswith("nominal and inner diameters met")
    assert_inside_and_apart(result.packing, walls)
    low, high = FB_PHI[d]
    assert low < result.packing.phi < high
