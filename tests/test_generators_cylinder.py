"""Generators in a cylinder: the soft quench (a harmonic curved wall), LS (collisions with
the cylinder as events) and FB (the cylinder pushes as a mirror image). Each packing lies
inside its cylinder, overlaps nothing, is not wrapped along the circle's axes, and reaches a
density that makes sense; the quench's cylinder terms are checked against the energy they
derive from, LS's event time and reflection against their formulas, FB's push against its
mirror partner's, and `calippso.jam` certifies a quench and an LS run."""

from __future__ import annotations

import numpy as np
import pytest

import calippso
import generators
from calippso import Boundaries
from calippso.geometry.neighbors import min_gap
from calippso.geometry.walls import cylinder_wall
from generators import diameters as dist

#: Relative overlap allowed between two particles or a particle and the cylinder
#: (round-off), × the diameter.
OVERLAP_TOLERANCE = 1e-9

#: (d, diameters) of the cylinder runs: bidisperse discs in a circle (1:1.4, which do not
#: crystallise) and equal spheres in a cylinder along z.
CASES = {"d2": (2, dist.bidisperse(128, 1.4)),
         "d3": (3, dist.monodisperse(128))}

#: Bands of the jammed-ish density of a quench of N = 128 in a cylinder: below the periodic
#: value (0.84 for these discs, 0.64 for spheres) by the looser layer at the curved wall
#: (a cylinder of N = 128 equal spheres is only ~5 diameters across).
QUENCH_PHI = {2: (0.76, 0.85), 3: (0.52, 0.63)}

#: The kernel of each minimiser (module, function), for the checkpoint test.
QUENCH_KERNELS = {"fire": ("_fire", "fire_run"), "lbfgs": ("_lbfgs", "lbfgs_run")}

#: Finite-difference step of the kernel checks (mean diameters) and their tolerance.
FD_STEP = 1e-7
FD_RTOL = 1e-6


def cylinder_of(d: int) -> Boundaries:
    """The cylinder of the tests: its circle in x, y (periodic along z in d = 3)."""
    return Boundaries.cylinder(d, ["x", "y"])


def radial_offsets(packing) -> np.ndarray:
    """Each centre's offset from the cylinder's axis in the circle's plane, shape (N, 2)."""
    a, b = packing.boundaries.cylinder_axes
    return packing.positions[:, [a, b]] - 0.5 * packing.box[[a, b]]


def assert_inside_and_apart(packing, boundaries: Boundaries) -> None:
    """The packing carries `boundaries`, every centre lies inside the cylinder, and no two
    particles overlap (minimum image along the periodic axes only)."""
    assert packing.boundaries == boundaries
    boundaries.check(packing.positions, packing.diameters, packing.box)
    a = boundaries.cylinder_axes[0]
    rho = np.linalg.norm(radial_offsets(packing), axis=1)
    clearance = 0.5 * packing.box[a] - rho - 0.5 * packing.diameters
    assert np.all(clearance >= -OVERLAP_TOLERANCE * packing.diameters)
    gap, overlapping = min_gap(packing.positions, packing.diameters, packing.box,
                               packing.periodic)
    assert overlapping == 0 or gap >= -OVERLAP_TOLERANCE


# ------------------------------------------------------------------ the kernel


def _energy_terms(x, s, scale, box, periodic, cylinder):
    """Harmonic forces, virial, energy and overlaps of `_fire.harmonic_forces`."""
    from generators import _fire
    from generators.cells import verlet_lists

    lists = _fire.pair_lists(*verlet_lists(x, box, scale * s, 0.5, periodic))
    f = np.zeros_like(x)
    pair_force = np.empty((lists[1].shape[0], x.shape[1]))
    sums = _fire.harmonic_forces(x, np.zeros_like(x), s, scale, box, *lists, pair_force, f,
                                 _fire.work_array(x.shape[0]), periodic, cylinder)
    return f, sums[5], sums[7], sums[6]


#: Four particles in a cylinder of diameter L = 3.6 in x, y (d = 3: periodic in z): 0 and 3
#: overlap the curved wall, 2 overlaps 1 and 3; 1 and 2 are near the axis.
KERNEL_X = np.array([[0.45, 1.5, 1.0], [1.5, 1.7, 1.1], [2.4, 2.2, 1.0], [3.0, 2.9, 1.2]])
KERNEL_S = np.array([1.0, 1.0, 1.2, 0.9])
KERNEL_BOX = np.full(3, 3.6)


@pytest.mark.parametrize("d", [2, 3])
def test_harmonic_cylinder_forces_and_virial_derive_from_the_energy(d):
    """In a cylinder: the force is −∂E/∂x and the virial a ∂E/∂a (the pressure's conjugate
    of the diameter scale, the centres fixed: the box shrinking affinely) to
    finite-difference accuracy; the cylinder pushes towards its axis."""
    periodic = np.zeros(d, dtype=bool)
    periodic[2:] = True
    x, s, box = KERNEL_X[:, :d].copy(), KERNEL_S, KERNEL_BOX[:d]
    scale = 1.02
    f, virial, energy, overlaps = _energy_terms(x, s, scale, box, periodic, (0, 1))
    rho = np.linalg.norm(x[:, :2] - box[0] / 2, axis=1)
    on_wall = rho + scale * s / 2 > box[0] / 2
    assert list(np.flatnonzero(on_wall)) == [0, 3]
    distance = np.linalg.norm(x[:, None] - x[None], axis=-1)     # no image: L > 2 r
    overlapping_pairs = np.triu(distance < scale * (s[:, None] + s[None]) / 2, 1).sum()
    assert overlaps == overlapping_pairs + 2
    for i in range(4):
        for mu in range(d):
            moved = [x.copy(), x.copy()]
            moved[0][i, mu] += FD_STEP
            moved[1][i, mu] -= FD_STEP
            derivative = (_energy_terms(moved[0], s, scale, box, periodic, (0, 1))[2]
                          - _energy_terms(moved[1], s, scale, box, periodic, (0, 1))[2]
                          ) / (2 * FD_STEP)
            assert f[i, mu] == pytest.approx(-derivative, rel=FD_RTOL, abs=1e-9)
    derivative = (_energy_terms(x, s, scale * np.exp(FD_STEP), box, periodic, (0, 1))[2]
                  - _energy_terms(x, s, scale * np.exp(-FD_STEP), box, periodic, (0, 1))[2]
                  ) / (2 * FD_STEP)
    assert virial == pytest.approx(derivative, rel=FD_RTOL)


def test_a_particle_overlapping_the_cylinder_has_the_energy_of_a_pair():
    """A lone particle overlapping the cylinder by δ = ρ + σ/2 − L/2 has the energy (δ/σ)²/2
    and the force δ/σ² along −ρ̂, and its virial is that force × (L/2 − ρ)."""
    periodic = np.array([False, False, True])
    x = np.array([[1.0, 0.8, 1.0]])
    box = np.full(3, 3.6)
    scale = 1.1
    f, virial, energy, overlaps = _energy_terms(x, np.ones(1), scale, box, periodic, (0, 1))
    offset = x[0, :2] - 1.8
    rho = np.linalg.norm(offset)
    delta = rho + scale / 2 - 1.8
    assert overlaps == 1 and delta > 0
    assert energy == pytest.approx(0.5 * (delta / scale) ** 2, rel=1e-12)
    np.testing.assert_allclose(f[0, :2], -delta / scale ** 2 * offset / rho, rtol=1e-12)
    assert f[0, 2] == 0.0
    assert virial == pytest.approx(delta / scale ** 2 * (1.8 - rho), rel=1e-12)


def test_cylinder_axes_are_not_flat_walls_nor_periodic():
    """Along the circle's axes there are no flat walls and no periodic images: a particle
    near a corner of the box (0.45 from x = 0) feels the cylinder's force only, and two
    particles pressed into opposite sides of the cylinder (0.4 apart through the periodic
    image) do not meet."""
    periodic = np.array([False, False])
    box = np.full(2, 3.6)
    corner = np.array([[0.45, 0.9]])
    f, _, _, overlaps = _energy_terms(corner, np.ones(1), 1.0, box, periodic, (0, 1))
    offset = corner[0] - 1.8
    rho = np.linalg.norm(offset)
    assert overlaps == 1
    np.testing.assert_allclose(f[0], -(rho + 0.5 - 1.8) * offset / rho, rtol=1e-12)
    opposite = np.array([[0.2, 1.8], [3.4, 1.8]])
    f, _, energy, overlaps = _energy_terms(opposite, np.ones(2), 1.0, box, periodic, (0, 1))
    assert overlaps == 2
    assert energy == pytest.approx(2 * 0.5 * (1.6 + 0.5 - 1.8) ** 2, rel=1e-12)
    np.testing.assert_allclose(f, [[0.3, 0.0], [-0.3, 0.0]], rtol=1e-12)


def test_wall_gaps_number_the_cylinder_2d():
    from generators._checks import wall_gaps

    x = np.array([[1.0, 0.8, 1.0], [1.8, 1.8, 0.2]])
    particle, wall, gaps = wall_gaps(x, np.ones(2), np.full(3, 3.6),
                                     np.array([False, False, True]), (0, 1))
    assert list(particle) == [0, 1] and list(wall) == [cylinder_wall(3)] * 2
    rho = np.linalg.norm(x[0, :2] - 1.8)
    assert gaps[0] == pytest.approx(2 * (1.8 - rho) - 1, rel=1e-14)
    assert gaps[1] == pytest.approx(2 * 1.8 - 1, rel=1e-14)


# ------------------------------------------------------------------ the soft quench


@pytest.fixture(scope="module")
def quenches(computed_once):
    return computed_once("cylinder_quenches", lambda: {
        name: generators.soft_quench(sizes, d, seed=1, boundaries=cylinder_of(d))
        for name, (d, sizes) in CASES.items()})


@pytest.mark.parametrize("name", list(CASES))
def test_quench_in_a_cylinder_is_inside_apart_and_jammed_ish(name, quenches):
    d, sizes = CASES[name]
    tube = cylinder_of(d)
    result = quenches[name]
    assert result.status.startswith("converged")
    assert_inside_and_apart(result.packing, tube)
    np.testing.assert_array_equal(result.packing.diameters, sizes)
    low, high = QUENCH_PHI[d]
    assert low < result.packing.phi < high
    assert result.extra["isostaticity_gap"] >= 0  # walls and the rotation counted
    assert result.contacts.shape[1] == 2 and result.contacts.max() < len(sizes)
    particle, wall = result.extra["wall_contacts"].T
    assert len(particle) > 0 and np.all(wall == cylinder_wall(d))
    # the contacts touch the cylinder: ρ + σ/2 within the shrink of L/2
    packing = result.packing
    rho = np.linalg.norm(radial_offsets(packing)[particle], axis=1)
    reach = (rho + packing.diameters[particle] / 2) / (packing.box[0] / 2)
    assert np.all(np.abs(reach - 1) < 10 * result.extra["max_overlap"])
    # the particles are in equilibrium, so the cylinder's forces on them add up to zero:
    # each is its overlap w / (2σ) (ε = 1) along −ρ̂
    offsets = radial_offsets(packing)[particle]
    sigma = packing.diameters[particle] / packing.diameters.mean()
    push = -(result.extra["wall_overlaps"] / (2 * sigma))[:, None] * offsets \
        / np.linalg.norm(offsets, axis=1)[:, None]
    assert np.linalg.norm(push.sum(axis=0)) < 1e-3 * np.abs(push).sum()


def test_circle_axes_are_not_wrapped(quenches):
    """No contact reaches through a periodic image along the circle's axes: with the
    minimum image along the periodic axes only, every contact is at its contact distance
    (up to the largest overlap before the shrink)."""
    for name, result in quenches.items():
        packing = result.packing
        i, j = result.contacts.T
        delta = packing.positions[i] - packing.positions[j]
        periodic = packing.periodic
        delta[:, periodic] -= packing.box[periodic] * np.round(delta[:, periodic]
                                                               / packing.box[periodic])
        sigma = (packing.diameters[i] + packing.diameters[j]) / 2
        gaps = np.linalg.norm(delta, axis=1) / sigma - 1
        assert np.all(np.abs(gaps) <= 10 * result.extra["max_overlap"]), name


def test_quench_in_a_cylinder_is_certified_by_jam(quenches):
    """The quench is a start next to its jamming point: jam certifies it isostatic, with
    cylinder contacts, at once."""
    result = calippso.jam(quenches["d2"].packing)
    assert result.isostatic
    assert result.n_wall_contacts > 0
    assert result.iterations <= 2
    assert result.force_balance <= 1e-12


@pytest.mark.parametrize("minimiser", ["fire", "lbfgs"])
def test_cylinder_quench_killed_mid_minimisation_resumes_bit_for_bit(tmp_path, monkeypatch,
                                                                     minimiser):
    """In a cylinder (bidisperse discs in a circle) a quench killed half-way through its
    steps resumes from its checkpoint and ends where the uninterrupted run ends, wall
    contacts and boundaries included; the checkpoint is refused by the periodic run."""
    import importlib

    tube = cylinder_of(2)
    sizes = dist.bidisperse(64, 1.4)
    reference = generators.soft_quench(sizes, 2, seed=7, minimiser=minimiser, boundaries=tube)
    module_name, kernel = QUENCH_KERNELS[minimiser]
    module = importlib.import_module(f"generators.{module_name}")
    real_run, taken = getattr(module, kernel), []

    class Crash(Exception):
        """Stands in for a run killed between two steps."""

    def crashing_run(*args):
        if sum(taken) >= 0.5 * reference.steps:
            raise Crash
        result = real_run(*args)
        taken.append(result[1])
        return result

    monkeypatch.setattr(module, kernel, crashing_run)
    path = tmp_path / "cylinder.npz"
    with pytest.raises(Crash):
        generators.soft_quench(sizes, 2, seed=7, checkpoint=path, checkpoint_every=0,
                               minimiser=minimiser, boundaries=tube)
    monkeypatch.setattr(module, kernel, real_run)
    resumed = generators.soft_quench(sizes, 2, seed=7, checkpoint=path, checkpoint_every=0,
                                     minimiser=minimiser, boundaries=tube)
    assert resumed.extra["resumed"]
    np.testing.assert_array_equal(resumed.packing.positions, reference.packing.positions)
    np.testing.assert_array_equal(resumed.packing.diameters, reference.packing.diameters)
    np.testing.assert_array_equal(resumed.packing.box, reference.packing.box)
    np.testing.assert_array_equal(resumed.contacts, reference.contacts)
    np.testing.assert_array_equal(resumed.extra["wall_contacts"],
                                  reference.extra["wall_contacts"])
    assert (resumed.steps, resumed.status) == (reference.steps, reference.status)
    assert resumed.packing.boundaries == tube
    with pytest.raises(ValueError, match="differs in boundaries"):
        generators.soft_quench(sizes, 2, seed=7, checkpoint=path, minimiser=minimiser)


# ------------------------------------------------------------------ Lubachevsky–Stillinger

#: Reduced pressure of the LS runs in a cylinder, and the band of their densities (N = 128,
#: a fast growth rate: below the periodic LS values, 0.84 for these discs and 0.64 for
#: spheres).
LS_PRESSURE = 1e5
LS_PHI = {2: (0.78, 0.86), 3: (0.54, 0.64)}


def _contact_residual(x, v, s, box, scale, rate, tau):
    """|ρ + w τ| − (L/2 − σ(τ)/2) of particle 0 in a cylinder in x, y (0 at contact)."""
    offset = x[0, :2] + v[0, :2] * tau - box[0] / 2
    return np.linalg.norm(offset) - (box[0] / 2 - s[0] * (scale + rate * tau) / 2)


def test_cylinder_event_meets_the_growing_sphere_and_reflects_with_the_growth():
    """A sphere of diameter 1 growing at s γ/2 = 0.1 in a cylinder of diameter 4 meets it when
    |ρ + w τ| = L/2 − σ(τ)/2; it leaves with the normal speed 2w − u (w = 0.1) along −ρ̂, its
    tangential velocity kept and σ/2 × the impulse in the virial. Receding from the wall it
    meets the far side (the later root); at rest it meets it when its growth closes the gap."""
    from generators.edmd import _cylinder_collision, _cylinder_event

    box, s, rate, cylinder = np.full(3, 4.0), np.array([1.0]), 0.2, (0, 1)
    x = np.array([[2.6, 2.3, 1.0]])
    v = np.array([[0.8, -0.1, 0.5]])
    tau = _cylinder_event(0, x, v, s, box, cylinder, 1.0, rate)
    assert 0 < tau < np.inf
    assert _contact_residual(x, v, s, box, 1.0, rate, tau) == pytest.approx(0.0, abs=1e-14)
    # no earlier contact: the gap is open on a fine grid before τ
    grid = np.linspace(0.0, tau, 200)[:-1]
    assert all(_contact_residual(x, v, s, box, 1.0, rate, t) < 0 for t in grid)
    x[0] += v[0] * tau
    scale = 1.0 + rate * tau
    normal = -(x[0, :2] - 2.0) / np.linalg.norm(x[0, :2] - 2.0)
    u, along = v[0, :2] @ normal, v[0, :2] @ np.array([-normal[1], normal[0]])
    virial = _cylinder_collision(0, x, v, s, box, cylinder, scale, rate)
    assert v[0, :2] @ normal == pytest.approx(2 * 0.1 - u, rel=1e-14)
    assert v[0, :2] @ np.array([-normal[1], normal[0]]) == pytest.approx(along, rel=1e-12)
    assert v[0, 2] == 0.5
    assert virial == pytest.approx(0.5 * scale * 2 * (0.1 - u), rel=1e-14)
    # just reflected (at contact, receding): the next contact is on the far side
    again = _cylinder_event(0, x, v, s, box, cylinder, scale, rate)
    assert again > 0.1
    assert _contact_residual(x, v, s, box, scale, rate, again) == pytest.approx(0.0, abs=1e-13)
    # at rest 0.5 from the axis: the gap 2 − 0.5 − 0.5 closes at the growth 0.1
    rest = _cylinder_event(0, np.array([[2.5, 2.0, 1.0]]), np.zeros((1, 3)), s, box,
                           cylinder, 1.0, rate)
    assert rest == pytest.approx(1.0 / 0.1, rel=1e-14)
    # approaching while touching (round-off): at once; without growth and at rest: never
    touching = np.array([[3.5, 2.0, 1.0]])
    assert _cylinder_event(0, touching, np.array([[0.1, 0.0, 0.0]]), s, box, cylinder,
                           1.0, 0.0) == 0.0
    assert _cylinder_event(0, touching, np.zeros((1, 3)), s, box, cylinder, 1.0,
                           0.0) == np.inf


def test_cylinder_axes_have_no_flat_wall_events():
    """Along the cylinder's axes `_wall_event` finds no flat wall, while a flat wall along
    another axis still meets the sphere."""
    from generators.edmd import _wall_event

    x, v, s = np.array([[2.0, 2.0, 1.0]]), np.array([[1.0, 1.0, -1.0]]), np.ones(1)
    box = np.full(3, 4.0)
    assert _wall_event(0, x, v, s, box, np.array([False, False, True]), 1.0, 0.0,
                       (0, 1))[0] == np.inf
    tau, wall = _wall_event(0, x, v, s, box, np.array([False, False, False]), 1.0, 0.0,
                            (0, 1))
    assert wall == 4 and tau == pytest.approx(0.5)


def test_elastic_cylinder_conserves_the_kinetic_energy():
    """At zero growth and without velocity rescaling, spheres bouncing off the cylinder and
    off each other keep their kinetic energy, stay inside and collide with it."""
    from generators.edmd import run_window

    tube = cylinder_of(3)
    start = generators.poisson(np.ones(40), 3, phi=0.05, seed=4, boundaries=tube)
    x = start.positions.copy()
    v = np.random.default_rng(4).standard_normal(x.shape)
    energy = np.sum(v ** 2)
    periodic = start.periodic.astype(bool)
    # a writable box, as the generators pass it: the kernel's compiled variant is reused
    box = np.array(start.box)
    _, _, virial, _, collisions, _ = run_window(x, v, np.ones(40), box, 1.0, 0.0, 1.0,
                                                4000, 10 ** 9, 0.1, np.inf, periodic, (0, 1))
    assert collisions == 4000 and virial > 0
    assert np.sum(v ** 2) == pytest.approx(energy, rel=1e-12)
    tube.check(x, np.ones(40), start.box)


@pytest.fixture(scope="module")
def ls_runs(computed_once):
    return computed_once("cylinder_ls_runs", lambda: {
        name: generators.lubachevsky_stillinger(sizes, d, seed=1, target_pressure=LS_PRESSURE,
                                                boundaries=cylinder_of(d))
        for name, (d, sizes) in CASES.items()})


@pytest.mark.parametrize("name", list(CASES))
def test_ls_in_a_cylinder_reaches_its_pressure_inside_and_apart(name, ls_runs):
    d, sizes = CASES[name]
    tube = cylinder_of(d)
    result = ls_runs[name]
    assert result.reduced_pressure >= LS_PRESSURE
    assert_inside_and_apart(result.packing, tube)
    np.testing.assert_allclose(result.packing.diameters, sizes, rtol=1e-14)
    low, high = LS_PHI[d]
    assert low < result.packing.phi < high
    # near jamming the spheres press on the cylinder: many within 1e-3 σ of contact
    packing = result.packing
    rho = np.linalg.norm(radial_offsets(packing), axis=1)
    gap = packing.box[0] / 2 - rho - packing.diameters / 2
    assert np.count_nonzero(gap < 1e-3 * packing.diameters) >= 10


def test_ls_in_a_cylinder_is_certified_by_jam(ls_runs):
    result = calippso.jam(ls_runs["d2"].packing)
    assert result.isostatic
    assert result.n_wall_contacts > 0
    assert result.force_balance <= 1e-12


@pytest.mark.parametrize("d, sizes", [(2, dist.bidisperse(64, 1.4)), (3, dist.monodisperse(64))])
def test_mls_in_a_cylinder_jams_inside_it(d, sizes):
    """MLS (the closest-jamming protocol) in a cylinder ends jammed inside it, and `jam`
    certifies the result: isostatic with the cylinder's contacts, balanced."""
    tube = cylinder_of(d)
    result = generators.closest_jamming(sizes, d, seed=1, final_rate=1e-2,
                                        boundaries=tube)
    assert result.status.startswith("jammed")
    assert_inside_and_apart(result.packing, tube)
    jammed = calippso.jam(result.packing)
    assert_inside_and_apart(jammed.packing, tube)
    assert jammed.isostatic and jammed.isostaticity_gap == 0
    assert jammed.force_balance <= 1e-12 and jammed.n_wall_contacts > 0


def test_ls_continues_a_cylinder_start_and_keeps_its_cylinder():
    """A start in a cylinder (Poisson points, shrunk to no overlap) is compressed in its own
    container, its box unchanged."""
    tube = cylinder_of(2)
    start = generators.poisson(dist.bidisperse(64, 1.4), 2, phi=0.2, seed=3, boundaries=tube)
    result = generators.lubachevsky_stillinger(start=start, target_pressure=1e3, seed=2)
    assert result.reduced_pressure >= 1e3
    assert_inside_and_apart(result.packing, tube)
    np.testing.assert_array_equal(result.packing.box, start.box)



def test_cylinder_ls_pushed_to_a_higher_pressure_is_the_direct_run(tmp_path):
    """In a cylinder an LS run stopped at p = 1e3 and continued to 1e5 from its checkpoint is
    the run made at 1e5 directly, bit for bit; the checkpoint is refused by the periodic
    run."""
    tube = cylinder_of(3)
    args = {"d": 3, "seed": 5, "target_pressure": 1e5, "boundaries": tube}
    sizes = dist.monodisperse(64)
    direct = generators.lubachevsky_stillinger(sizes, **args)
    path = tmp_path / "cylinder_ls"
    low = generators.lubachevsky_stillinger(sizes, checkpoint=path,
                                            **{**args, "target_pressure": 1e3})
    assert 1e3 <= low.reduced_pressure < 1e5
    high = generators.lubachevsky_stillinger(sizes, checkpoint=path, **args)
    assert high.extra["resumed"]
    np.testing.assert_array_equal(high.packing.positions, direct.packing.positions)
    np.testing.assert_array_equal(high.packing.diameters, direct.packing.diameters)
    np.testing.assert_array_equal(high.packing.box, direct.packing.box)
    assert (high.steps, high.reduced_pressure) == (direct.steps, direct.reduced_pressure)
    assert high.packing.boundaries == tube
    with pytest.raises(ValueError, match="differs in boundaries"):
        generators.lubachevsky_stillinger(sizes, checkpoint=path, **{**args, "boundaries": None})


# ------------------------------------------------------------------ force-biased

#: Band of the FB densities in a cylinder (N = 128, default contraction): a loose start,
#: below the periodic FB values.
FB_PHI = {2: (0.72, 0.84), 3: (0.48, 0.62)}


def test_fb_cylinder_push_is_the_push_of_the_mirror_image():
    """A sphere of nominal diameter 1 at δ = L/2 − ρ = 0.3 from a cylinder of diameter 3 is
    pushed along −ρ̂ by σ² (1 − (2δ)²/σ²), the Bezrukov push of its mirror partner at 2δ, and
    the inner scale becomes 2δ/s; the cylinder's axes have no flat walls (a sphere 0.45 from
    x = 0, near a corner, feels the cylinder's push only); a centre carried past the
    cylinder is put back on it."""
    from generators.fb import _keep_between_walls, _wall_pushes

    box, periodic = np.full(2, 3.0), np.array([False, False])
    direction = np.array([0.6, -0.8])
    x = np.array([1.5 + 1.2 * direction, [1.5, 1.5]])
    force = np.zeros_like(x)
    inner = _wall_pushes(x, np.ones(2), box, periodic, 1.0, force, np.inf, (0, 1))
    np.testing.assert_allclose(force[0], -(1.0 - 0.6 ** 2) * direction, rtol=1e-12)
    assert np.all(force[1] == 0.0)
    assert inner == pytest.approx(0.6, rel=1e-12)
    corner = np.array([[0.45, 0.9]])
    force = np.zeros_like(corner)
    _wall_pushes(corner, np.ones(1), box, periodic, 1.0, force, np.inf, (0, 1))
    offset = corner[0] - 1.5
    rho = np.linalg.norm(offset)
    np.testing.assert_allclose(force[0], -(1.0 - (2 * (1.5 - rho)) ** 2) * offset / rho,
                               rtol=1e-12)
    outside = np.array([1.5 + 1.6 * direction])
    _keep_between_walls(outside, box, periodic, (0, 1))
    np.testing.assert_allclose(outside[0], 1.5 + 1.5 * direction, rtol=1e-14)


@pytest.mark.parametrize("name", list(CASES))
def test_fb_in_a_cylinder_is_inside_and_apart(name):
    d, sizes = CASES[name]
    tube = cylinder_of(d)
    result = generators.force_biased(sizes, d, seed=1, boundaries=tube)
    assert result.status.startswith("nominal and inner diameters met")
    assert_inside_and_apart(result.packing, tube)
    np.testing.assert_allclose(result.packing.diameters, sizes, rtol=1e-14)
    low, high = FB_PHI[d]
    assert low < result.packing.phi < high
