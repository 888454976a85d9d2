"""Flat hard walls: the boundaries value, the geometry along bounded axes, and `jam` between
walls (rows, forces on the walls, isostaticity with the translations the walls leave,
rattlers counted with wall contacts, the pressure on the walls by the virial)."""

from __future__ import annotations

import numpy as np
import pytest

import calippso
from calippso import Boundaries, Packing
from calippso.geometry.contacts import isostaticity_gap
from calippso.geometry.neighbors import NeighborSearch
from calippso.geometry.periodic import minimum_image, wrap
from calippso.geometry.rattlers import remove_rattlers
from calippso.geometry.walls import out_of_layer_moves

from configurations import lognormal, random_sequential_addition

#: Largest net force on a particle, relative to the mean force.
BALANCE = 1e-12
#: Largest overlap of two particles or of a particle and a wall (relative gap).
OVERLAP = 1e-14
#: A contact's relative gap is at most this.
CONTACT_GAP = 1e-9


def walled_start(n: int, d: int, axes, seed: int = 1, polydisperse: bool = False) -> Packing:
    """A random non-overlapping start between flat walls along `axes`."""
    sizes = lognormal(n, 0.1, seed) if polydisperse else None
    phi = 0.45 if d == 2 else 0.3
    return random_sequential_addition(n, d, phi, seed, sizes, Boundaries.walls(d, axes))


# ---------------------------------------------------------------------- the value type
def test_default_is_periodic_and_unchanged():
    packing = Packing(np.random.default_rng(0).random((10, 3)) * 5, np.ones(10), 5.0)
    assert packing.boundaries == Boundaries.all_periodic(3)
    assert packing.boundaries.is_periodic and packing.boundaries.zero_modes == 3
    assert packing.volume == pytest.approx(125.0)


def test_boundaries_kinds_and_counts():
    walls = Boundaries.walls(3, "x,y".split(","))
    assert walls.kinds == ("walls", "walls", "periodic")
    assert walls.wall_axes == (0, 1) and walls.n_periodic == 1 and walls.zero_modes == 1
    assert walls.periodic.tolist() == [False, False, True]
    assert Boundaries.from_text(str(walls)) == walls
    cylinder = Boundaries.cylinder(3, (0, 1))
    assert cylinder.cylinder_axes == (0, 1)
    # a cylinder leaves the translation along its axis and the rotation about it
    assert cylinder.zero_modes == 2
    assert cylinder.volume(np.array([2.0, 2.0, 3.0])) == pytest.approx(np.pi * 3.0)


@pytest.mark.parametrize("make, message", [
    (lambda: Boundaries(("periodic", "wall")), "unknown boundary kind"),
    (lambda: Boundaries(("cylinder", "periodic", "periodic")), "exactly two axes"),
    (lambda: Boundaries.walls(3, "q"), "unknown axis"),
    (lambda: Boundaries.walls(2, [0, 0]), "given twice"),
    (lambda: Boundaries.walls(2, [2]), "out of range"),
])
def test_bad_boundaries_are_refused_in_one_line(make, message):
    with pytest.raises(ValueError, match=message) as error:
        make()
    assert "\n" not in str(error.value)


def test_particle_outside_or_overlapping_a_wall_is_refused():
    walls = Boundaries.walls(2, [0])
    positions = np.array([[0.5, 1.0], [2.0, 3.0], [3.0, 1.5]])
    Packing(positions, np.ones(3), 6.0, walls)          # touching the wall is inside
    for x, where in ((0.4, "overlapping its wall"), (-1.0, "outside"), (5.7, "crosses")):
        moved = positions.copy()
        moved[0, 0] = x
        with pytest.raises(ValueError, match=where) as error:
            Packing(moved, np.ones(3), 6.0, walls)
        assert "\n" not in str(error.value)
    with pytest.raises(ValueError, match="container smaller than a particle"):
        Packing(np.array([[0.5, 0.5]]), np.array([1.2]), [1.0, 5.0], walls)
    with pytest.raises(ValueError, match="boundaries have 3 axes"):
        Packing(positions, np.ones(3), 6.0, Boundaries.walls(3, [0]))


def test_cylinder_needs_its_particles_inside_the_circle():
    cylinder = Boundaries.cylinder(3, (0, 1))
    inside = np.array([[2.0, 2.0, 1.0], [3.4, 2.0, 2.0]])
    Packing(inside, np.ones(2), [4.0, 4.0, 5.0], cylinder)
    with pytest.raises(ValueError, match="the cylinder"):
        Packing(inside + [0.2, 0.0, 0.0], np.ones(2), [4.0, 4.0, 5.0], cylinder)
    with pytest.raises(ValueError, match="equal box sides"):
        Packing(inside, np.ones(2), [4.0, 4.5, 5.0], cylinder)


# ---------------------------------------------------------------------- geometry
def test_minimum_image_and_wrap_only_along_periodic_axes():
    box = np.array([4.0, 4.0])
    periodic = np.array([False, True])
    delta = np.array([[3.5, 3.5], [-3.5, -3.5]])
    assert minimum_image(delta, box, periodic).tolist() == [[3.5, -0.5], [-3.5, 0.5]]
    assert minimum_image(delta, box).tolist() == [[-0.5, -0.5], [0.5, 0.5]]
    assert wrap(np.array([[3.9, 4.5]]), box, periodic).tolist() == [[3.9, 0.5]]


def test_pairs_do_not_meet_across_a_wall():
    box = np.array([6.0, 6.0])
    positions = np.array([[0.5, 3.0], [5.5, 3.0], [3.0, 0.5], [3.0, 5.5]])
    periodic = NeighborSearch(positions, np.ones(4), box).pairs_within(1.5)
    walled = NeighborSearch(positions, np.ones(4), box, np.array([False, True]))
    assert len(periodic) == 2
    pairs = walled.pairs_within(1.5)
    assert (pairs.i.tolist(), pairs.j.tolist()) == ([2], [3])
    assert pairs.distances[0] == pytest.approx(1.0)


def test_rattler_rule_counts_wall_contacts():
    # particle 0 has two particle contacts and one wall contact: d + 1 = 3 in d = 2
    i, j = np.array([0, 0, 1, 1, 2]), np.array([1, 2, 2, 3, 3])
    rattlers, _ = remove_rattlers(4, 2, i, j)
    assert rattlers[0]
    rattlers, kept = remove_rattlers(4, 2, i, j, wall_particle=np.array([0, 3]))
    assert not rattlers.any() and kept.all()


def test_out_of_layer_moves_lift_in_plane_particles_and_nothing_else():
    """Equal discs side by side at the wall y = 0: those whose touching pairs all lie in the
    layer, without a wall contact, leave it, never into an overlap; the others stay."""
    box = np.array([10.0, 10.0])
    positions = np.array([[3.0, 0.5], [4.0, 0.5], [5.0, 0.5], [4.0, 1.5 + 5e-4]])
    search = NeighborSearch(positions, np.ones(4), box, np.array([True, False]))
    moved = out_of_layer_moves(search, (1,), np.array([0]), 1e-3, 1e-9, 1e-9)
    lift = moved[:, 1] - positions[:, 1]
    assert lift[0] == 0 and lift[3] == 0 and np.all(moved[:, 0] == positions[:, 0])
    # particle 1 is held back by particle 3 above it (gap 5e-4), particle 2 is free
    assert 0 < lift[1] <= 5e-4 and lift[2] == pytest.approx(1e-3)
    after = NeighborSearch(moved, np.ones(4), box, np.array([True, False]))
    assert after.pairs_within(1.5).smallest_gap() >= 0
    assert out_of_layer_moves(search, (1,), np.array([0, 1, 2]), 1e-3, 1e-9, 1e-9) is None


# ---------------------------------------------------------------------- jam between walls
def _wall_distance(packing: Packing, particle: np.ndarray, wall: np.ndarray) -> np.ndarray:
    axis = wall // 2
    x = packing.positions[particle, axis]
    return np.where(wall % 2 == 0, x, packing.box[axis] - x)


def assert_jammed_between_walls(result) -> None:
    """Everything checked from the returned geometry, by brute force."""
    packing, d = result.packing, result.d
    boundaries = packing.boundaries
    assert result.converged, result.status
    # no overlap: every pair (minimum image along periodic axes only), every wall
    delta = packing.positions[:, None, :] - packing.positions[None, :, :]
    delta -= np.where(packing.periodic, packing.box, 0.0) * np.round(delta / packing.box)
    sigma = 0.5 * (packing.diameters[:, None] + packing.diameters[None, :])
    gaps = np.linalg.norm(delta, axis=2) / sigma - 1
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() >= -OVERLAP
    for axis in boundaries.wall_axes:
        x, radius = packing.positions[:, axis], packing.diameters / 2
        assert np.min(np.minimum(x, packing.box[axis] - x) / radius - 1) >= -OVERLAP
    # contacts touch, forces positive, mean 1 over particle and wall contacts
    i, j = result.contacts.T
    vectors = delta[i, j]
    distances = np.linalg.norm(vectors, axis=1)
    assert np.abs(distances / sigma[i, j] - 1).max() < CONTACT_GAP
    particle, wall = result.wall_contacts.T
    assert result.n_wall_contacts > 0
    assert np.all(np.isin(wall // 2, boundaries.wall_axes))
    assert np.abs(_wall_distance(packing, particle, wall) / (packing.diameters[particle] / 2)
                  - 1).max() < CONTACT_GAP
    assert np.all(result.forces > 0) and np.all(result.wall_forces > 0)
    every = np.concatenate([result.forces, result.wall_forces])
    assert every.mean() == pytest.approx(1.0, rel=1e-12)
    # every stable particle in balance, with the walls' forces (along +e at 0, -e at L)
    net = np.zeros((packing.n, d))
    normals = vectors / distances[:, None]
    np.add.at(net, i, result.forces[:, None] * normals)
    np.add.at(net, j, -result.forces[:, None] * normals)
    np.add.at(net, (particle, wall // 2), np.where(wall % 2 == 0, 1.0, -1.0) * result.wall_forces)
    assert np.abs(net).max() <= BALANCE
    assert result.force_balance <= BALANCE
    # rattlers: recursive rule with the wall contacts; no contact of a rattler
    counts = np.bincount(np.concatenate([result.contacts.ravel(), particle]),
                         minlength=packing.n)
    assert np.all(counts[~result.rattlers] >= d + 1)
    assert not result.rattlers[particle].any()
    # isostatic: N_c (pair + wall) = d N_s + 1 - (periodic axes)
    n_stable = int(np.count_nonzero(~result.rattlers))
    n_contacts = result.contacts.shape[0] + particle.shape[0]
    assert n_contacts == d * n_stable + 1 - boundaries.n_periodic, result.status
    assert result.isostatic and result.isostaticity_gap == 0
    assert isostaticity_gap(n_contacts, n_stable, d, boundaries.n_periodic) == 0
    # the two walls of an axis: equal and opposite forces; pressure by the virial
    loads = result.wall_loads
    volume = packing.volume
    for axis in range(d):
        if axis not in boundaries.wall_axes:
            assert np.all(loads[axis] == 0) and np.isnan(result.wall_pressures[axis]).all()
            continue
        assert loads[axis, 0] < 0 < loads[axis, 1]
        assert abs(loads[axis, 0] + loads[axis, 1]) <= BALANCE * loads[axis, 1]
        # Σ_i x_iμ (net force)_μ = 0  =>  L_μ F_μ = Σ_pairs f r_μ²/|r| + Σ_walls(μ) f σ_i/2
        at_axis = wall // 2 == axis
        virial = (np.sum(result.forces * vectors[:, axis] ** 2 / distances)
                  + np.sum(result.wall_forces[at_axis] * packing.diameters[particle[at_axis]]
                           / 2))
        assert result.wall_pressures[axis] * volume == pytest.approx([virial, virial],
                                                                      rel=1e-10)


@pytest.mark.parametrize("d, n, axes, polydisperse", [
    (2, 128, [0], True),
    (2, 64, [0, 1], True),
    pytest.param(3, 128, [0], False, marks=pytest.mark.slow),
    pytest.param(3, 128, [0, 1], True, marks=pytest.mark.slow),
    (3, 64, [0, 1, 2], True),
    pytest.param(3, 128, [0, 1], False, marks=pytest.mark.slow),
])
def test_jam_between_flat_walls(d, n, axes, polydisperse):
    start = walled_start(n, d, axes, polydisperse=polydisperse)
    result = calippso.jam(start)
    assert_jammed_between_walls(result)
    assert result.packing.boundaries == start.boundaries
    assert any("contact pivots skipped" in note for note in result.notes)
    # the Newton stage solves the pair and wall contact equations and certifies the point
    assert result.stop_reason is calippso.StopReason.CERTIFIED_NEWTON
    assert result.history["stage"].tolist().count("newton") == 1


@pytest.mark.parametrize("d, n, axes", [(2, 128, [0]), (3, 64, [0, 1, 2])])
def test_newton_between_walls_ends_where_the_lps_end(d, n, axes):
    """The Newton stage with wall contacts reaches the jamming point that the LP loop alone
    converges to: the same φ_J (to 1e-9), particle contacts and wall contacts."""
    start = walled_start(n, d, axes, polydisperse=True)
    newton = calippso.jam(start)
    lps = calippso.jam(start, newton=False)
    assert newton.stop_reason is calippso.StopReason.CERTIFIED_NEWTON
    assert lps.stop_reason is calippso.StopReason.CONVERGED
    assert_jammed_between_walls(lps)
    assert newton.iterations < lps.iterations
    assert newton.packing.phi == pytest.approx(lps.packing.phi, abs=1e-9)
    np.testing.assert_array_equal(newton.contacts, lps.contacts)
    np.testing.assert_array_equal(newton.wall_contacts, lps.wall_contacts)
    np.testing.assert_allclose(newton.wall_forces, lps.wall_forces, rtol=1e-6)


def test_walls_leave_a_periodic_run_unchanged():
    """A periodic packing gives no wall keys and the same result as before walls existed:
    the default boundaries take the periodic fast path everywhere."""
    start = random_sequential_addition(32, 2, 0.5, seed=3, diameters=lognormal(32, 0.1, 3))
    result = calippso.jam(start)
    assert result.n_wall_contacts == 0 and not np.any(result.wall_loads)
    assert "boundaries" not in result.to_arrays()
    assert not any("wall" in note for note in result.notes)


def test_a_loose_walled_start_has_no_network_to_certify():
    """A random start between walls is far from jamming: network first finds no isostatic
    network in its gaps, so ``network_first="require"`` fails in one line."""
    start = walled_start(64, 2, [0])
    with pytest.raises(calippso.JammingError, match="network_first='require'"):
        calippso.jam(start, network_first="require")


@pytest.mark.parametrize("boundaries, d, n", [
    (Boundaries.walls(3, [0]), 3, 128),
    (Boundaries.walls(2, [0, 1]), 2, 64),
    # the cylinder (slow): its Newton stage is tested fast in test_cylinder.py
    pytest.param(Boundaries.cylinder(3, (0, 1)), 3, 128, marks=pytest.mark.slow),
])
def test_a_near_jammed_packing_in_a_container_is_certified_with_no_lp(boundaries, d, n):
    """A jammed packing in a container, moved by 1e-9 and shrunk by 1e-8, comes back to the
    same φ_J (to 1e-9) and the same particle and wall contacts with no LP: its network is read
    from the gaps of the pairs and walls and certified by the Newton stage."""
    start = random_sequential_addition(n, d, 0.45 if d == 2 else 0.3, 1, lognormal(n, 0.1, 1),
                                       boundaries)
    jammed = calippso.jam(start)
    packing = jammed.packing
    moved = packing.positions + 1e-9 * np.random.default_rng(0).standard_normal(
        packing.positions.shape)
    again = calippso.jam(Packing(moved, packing.diameters * (1 - 1e-8), packing.box,
                                 boundaries), network_first="require")
    assert again.stop_reason is calippso.StopReason.NETWORK_FIRST and again.iterations == 0
    assert again.packing.phi == pytest.approx(packing.phi, abs=1e-9)
    np.testing.assert_array_equal(again.contacts, jammed.contacts)
    np.testing.assert_array_equal(again.wall_contacts, jammed.wall_contacts)
    assert again.isostatic and again.force_balance <= BALANCE


def test_poisson_places_centres_inside_the_container():
    generators = pytest.importorskip("generators")
    walls = Boundaries.walls(3, [0, 2])
    start = generators.poisson(np.linspace(0.8, 1.2, 200), 3, phi=0.3, seed=2, boundaries=walls)
    assert start.boundaries == walls
    radius = start.diameters / 2
    for axis in (0, 2):
        x = start.positions[:, axis]
        assert np.all(x >= radius) and np.all(x <= start.box[axis] - radius)
    assert start.phi == pytest.approx(0.3)
    cylinder = Boundaries.cylinder(3, (0, 1))
    tube = generators.poisson(np.ones(200), 3, phi=0.3, seed=2, boundaries=cylinder)
    offset = tube.positions[:, :2] - tube.box[0] / 2
    assert np.all(np.linalg.norm(offset, axis=1) <= (tube.box[0] - 1) / 2)
    assert tube.phi == pytest.approx(0.3)


def test_packing_generation_rectangle_is_read_jammed_and_verified(tmp_path):
    """A mode-3 folder written by hand in PackingGeneration's format (nominal diameters,
    porosities in the .nfo, walls in x and y, periodic z) reads as walls in x, y; it jams."""
    start = walled_start(96, 3, [0, 1], seed=5, polydisperse=True)
    theoretical = 0.45
    final = 1.0 - start.phi
    scale = ((1.0 - final) / (1.0 - theoretical)) ** (1.0 / 3.0)
    folder = tmp_path / "rectangle"
    folder.mkdir()
    records = np.column_stack([start.positions, start.diameters / scale]).astype("<f8")
    records.tofile(folder / "packing.xyzd")
    (folder / "packing.nfo").write_text(
        f"N: {start.n}\n Dimensions: {' '.join(map(str, start.box))}\n"
        f" Theoretical Porosity: {theoretical:.17g}\nFinal Porosity: {final:.17g} "
        f"(Tolerance: 1.000100)\n")
    (folder / "generation.conf").write_text(
        f"Particles count: {start.n}\nPacking size: {' '.join(f'{v:.17g}' for v in start.box)}\n"
        f"Generation start: 0\nSeed: 5\nSteps to write: 1000\nBoundaries mode: 3\n"
        f"Contraction rate: 0.01\nGeneration mode: 1\n")
    packing = calippso.read(folder)
    assert packing.boundaries == Boundaries.walls(3, [0, 1])
    np.testing.assert_allclose(packing.diameters, start.diameters, rtol=1e-14)
    assert_jammed_between_walls(calippso.jam(packing))


def test_analysis_sees_the_walls():
    """Gaps are measured without images across a wall; the opening response, which does not
    know wall contacts, refuses a box with walls in one line."""
    from calippso.analysis.gaps import gaps
    from calippso.analysis.response import opening_response

    result = calippso.jam(walled_start(64, 2, [0], polydisperse=True))
    packing = result.packing
    h = gaps(result, max_gap=0.5)
    stable = ~result.rattlers
    delta = packing.positions[:, None, :] - packing.positions[None, :, :]
    delta[..., 1] -= packing.box[1] * np.round(delta[..., 1] / packing.box[1])
    sigma = 0.5 * (packing.diameters[:, None] + packing.diameters[None, :])
    every = np.linalg.norm(delta, axis=2) / sigma - 1
    upper = np.triu(np.ones_like(every, dtype=bool), 1) & stable[:, None] & stable[None, :]
    expected = np.sort(every[upper & (every > 1e-11) & (every <= 0.5)])
    np.testing.assert_allclose(h, expected, rtol=1e-12)
    with pytest.raises(ValueError, match="periodic packings only"):
        opening_response(result)
