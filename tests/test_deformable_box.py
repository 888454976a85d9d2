"""The sheared periodic box (a general box matrix) and the deformable box of `jam`."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from calippso import Boundaries, Packing
from calippso.io import read, write
from calippso.geometry.periodic import (lattice_minimum_image, reduce_lattice,
                                        shortest_lattice_vector)


def _sheared_matrix(d: int, rng) -> np.ndarray:
    """A strongly sheared box: a random upper-triangular cell times an integer shear."""
    base = np.triu(rng.normal(size=(d, d))) + np.diag(rng.uniform(2.0, 4.0, size=d))
    shear = np.eye(d) + np.triu(rng.integers(-4, 5, size=(d, d)), 1)
    return base @ shear


@pytest.mark.parametrize("d", [2, 3, 4])
def test_lattice_minimum_image_matches_brute_force(d):
    rng = np.random.default_rng(d)
    for _ in range(5):
        matrix = _sheared_matrix(d, rng)
        delta = rng.normal(scale=8.0, size=(300, d))
        image = lattice_minimum_image(delta, matrix)
        shift = np.linalg.solve(matrix, (image - delta).T)
        assert np.allclose(shift, np.rint(shift), atol=1e-9)   # the same point of the lattice
        reach = range(-4, 5) if d < 4 else range(-2, 3)
        offsets = np.array(list(itertools.product(reach, repeat=d)), float) @ matrix.T
        candidates = image[:, None, :] + offsets[None]
        brute = np.sqrt(np.einsum("nkd,nkd->nk", candidates, candidates)).min(axis=1)
        assert np.all(np.linalg.norm(image, axis=1) <= brute + 1e-10)


def test_reduction_keeps_the_lattice_and_shortens_it():
    rng = np.random.default_rng(7)
    matrix = _sheared_matrix(3, rng)
    reduced = reduce_lattice(matrix)
    change = np.linalg.solve(matrix, reduced)
    assert np.allclose(change, np.rint(change), atol=1e-9)
    assert abs(abs(np.linalg.det(change)) - 1.0) < 1e-9
    assert np.linalg.norm(reduced, axis=0).max() <= np.linalg.norm(matrix, axis=0).max()
    assert shortest_lattice_vector(matrix) <= np.linalg.norm(reduced, axis=0).min() + 1e-12


def _sheared_packing(d: int = 3, n: int = 20) -> Packing:
    rng = np.random.default_rng(3)
    matrix = np.eye(d) * 6.0 + np.triu(np.full((d, d), 2.5), 1)
    rotation, _ = np.linalg.qr(rng.normal(size=(d, d)))
    rotation *= np.sign(np.linalg.det(rotation))
    return Packing.sheared(rng.uniform(0, 6, size=(n, d)) @ rotation.T, np.full(n, 0.5),
                           rotation @ matrix)


def test_sheared_packing_is_upper_triangular_with_its_volume():
    packing = _sheared_packing()
    assert packing.is_sheared
    assert np.allclose(np.tril(packing.box_matrix, -1), 0.0)
    assert np.allclose(np.diag(packing.box_matrix), packing.box)
    assert packing.volume == pytest.approx(6.0**3, rel=1e-12)
    wrapped = packing.wrapped()
    fractional = np.linalg.solve(packing.box_matrix, wrapped.positions.T)
    assert fractional.min() >= 0.0 and fractional.max() < 1.0
    delta = wrapped.positions[:, None] - packing.positions[None]
    same = packing.minimum_image(np.diagonal(delta).T)
    assert np.abs(same).max() < 1e-9


def test_rectangular_box_matrix_is_the_plain_box():
    packing = Packing(np.zeros((3, 2)) + [[0, 0], [1, 1], [2, 2]], np.full(3, 0.5), [4.0, 5.0],
                      None, np.diag([4.0, 5.0]))
    assert packing.box_matrix is None and not packing.is_sheared


def test_bad_box_matrices_are_refused():
    with pytest.raises(ValueError, match="upper triangular"):
        Packing(np.zeros((1, 2)), [0.5], [4.0, 4.0], None, [[4.0, 0.0], [1.0, 4.0]])
    with pytest.raises(ValueError, match="diagonal"):
        Packing(np.zeros((1, 2)), [0.5], [4.0, 4.0], None, [[4.0, 1.0], [0.0, 5.0]])
    with pytest.raises(ValueError, match="shortest box vector"):
        Packing.sheared(np.zeros((1, 2)), [1.0], [[4.0, 3.9], [0.0, 0.3]])


def test_sheared_packing_round_trips_through_npz_and_h5(tmp_path):
    packing = _sheared_packing()
    for name in ("p.npz", "p.h5"):
        if name.endswith(".h5"):
            pytest.importorskip("h5py")
        back = read(write(packing, tmp_path / name))
        assert np.array_equal(back.box_matrix, packing.box_matrix)
        assert np.array_equal(back.positions, packing.positions)
        assert back.phi == packing.phi


@pytest.mark.parametrize("name", ["p.xyz", "p.gsd", "p.dat", "p.xyzd"])
def test_rectangular_formats_refuse_a_sheared_box(tmp_path, name):
    if name.endswith(".gsd"):
        pytest.importorskip("gsd")
    with pytest.raises(ValueError, match="sheared .*write .npz or .h5"):
        write(_sheared_packing(), tmp_path / name)


def test_fixed_box_jam_refuses_a_sheared_box():
    from calippso import jam

    with pytest.raises(ValueError, match="box='deformable'"):
        jam(_sheared_packing())


# ----------------------------------------------------------------------------- jam(box=...)

import lattices  # noqa: E402
from configurations import ls_packing  # noqa: E402

from calippso import StopReason, jam, jamming_category  # noqa: E402
from calippso.certification.strict_certificate import floppy_strict_rows  # noqa: E402
from calippso.deformable import strict_zero_modes  # noqa: E402

#: Round-off tolerances of the checks (relative to the diameters, and to the mean force).
OVERLAP_TOLERANCE = 1e-12
BALANCE_TOLERANCE = 1e-12
CONTACT_GAP_TOLERANCE = 1e-9
ISOTROPY_TOLERANCE = 1e-9


def _all_gaps(packing: Packing) -> np.ndarray:
    """Relative gaps of every pair, by brute force with the sheared minimum image."""
    i, j = np.triu_indices(packing.n, 1)
    delta = packing.minimum_image(packing.positions[i] - packing.positions[j])
    sigma = 0.5 * (packing.diameters[i] + packing.diameters[j])
    return np.linalg.norm(delta, axis=1) / sigma - 1.0


def assert_strictly_jammed(result) -> None:
    """Converged, overlap-free, contacts that touch, positive forces of mean 1 balanced on
    every stable particle at the returned geometry, an isotropic stress that is the forces'
    virial sum, at least the strict count of contacts."""
    packing, d = result.packing, result.d
    assert result.converged, result.status
    assert result.box_mode == "deformable" and result.category == "strict"
    assert _all_gaps(packing).min() >= -OVERLAP_TOLERANCE
    i, j = result.contacts.T
    vectors = packing.minimum_image(packing.positions[i] - packing.positions[j])
    distances = np.linalg.norm(vectors, axis=1)
    sigma = 0.5 * (packing.diameters[i] + packing.diameters[j])
    assert np.abs(distances / sigma - 1.0).max() < CONTACT_GAP_TOLERANCE
    assert np.all(result.forces > 0) and result.forces.mean() == pytest.approx(1.0, rel=1e-12)
    net = np.zeros((packing.n, d))
    normals = vectors / distances[:, None]
    np.add.at(net, i, result.forces[:, None] * normals)
    np.add.at(net, j, -result.forces[:, None] * normals)
    assert np.abs(net).max() <= BALANCE_TOLERANCE
    assert result.force_balance <= BALANCE_TOLERANCE
    virial = np.einsum("k,ka,kb->ab", result.forces / distances, vectors, vectors)
    assert np.allclose(result.stress, virial / packing.volume, rtol=0.0,
                       atol=1e-12 * result.pressure)
    assert result.stress_anisotropy <= ISOTROPY_TOLERANCE
    assert result.pressure == pytest.approx(
        float(result.forces @ distances) / (d * packing.volume), rel=1e-12)
    n_stable = int(np.count_nonzero(~result.rattlers))
    assert result.n_contacts >= d * (n_stable - 1) + d * (d + 1) // 2, result.status
    assert result.isostaticity_gap == result.n_contacts - (
        d * (n_stable - 1) + d * (d + 1) // 2)


def test_strict_count_is_the_fixed_box_count_plus_the_box_shape():
    for d in range(2, 6):
        translations, shape_at_fixed_volume = d, d * (d + 1) // 2 - 1
        assert strict_zero_modes(Boundaries.all_periodic(d)) == (translations
                                                                - shape_at_fixed_volume)


@pytest.mark.parametrize("d", [2, 3])
def test_lp_rows_are_the_linearised_distances_with_the_strain_on_boundary_pairs_only(d):
    """Each row of the deformable LP is n·Δr − γσ²/(2|r|) for the pair's exact change Δr =
    s'_i − s'_j + ε m (s' the displacements with their affine part, m the pair's lattice
    vector): the strain enters the rows of the pairs across the boundary, and no other."""
    from calippso.deformable import _images, strain_count, strain_matrix, strained_lp
    from calippso.geometry.walls import empty_walls
    from calippso.geometry.sheared_search import sheared_pairs_within

    rng = np.random.default_rng(d)
    n = 40
    packing = Packing.sheared(rng.uniform(0.0, 6.0, size=(n, d)), np.full(n, 0.9),
                              np.eye(d) * 6.0 + np.triu(np.full((d, d), 2.5), 1))
    scale = packing.mean_diameter
    positions, diameters = packing.positions / scale, packing.diameters / scale
    matrix = packing.lattice / scale
    pairs = sheared_pairs_within(positions, diameters, matrix, 2.0)
    images = _images(positions, matrix, pairs)
    k = strain_count(d)
    pinned = np.zeros((n, d), dtype=bool)
    pinned[0] = True
    periodic = Boundaries.all_periodic(d)
    lp = strained_lp(pairs, images, empty_walls(d), n, 0.05, 0.01, pinned, periodic)
    moves, strain, gamma = rng.normal(size=(n, d)), rng.normal(size=k), 0.3
    variables = np.concatenate([moves.ravel(), strain, [gamma]])
    change = (moves[pairs.i] - moves[pairs.j]) + images @ strain_matrix(strain, periodic.periodic).T
    normals = pairs.vectors / pairs.distances[:, None]
    expected = (np.einsum("md,md->m", normals, change)
                - gamma * pairs.sigma**2 / (2.0 * pairs.distances))
    assert np.allclose(lp.matrix @ variables, expected, rtol=0.0, atol=1e-12)
    # the images are lattice vectors, and nonzero exactly where the pair crosses the boundary
    cells = np.linalg.solve(matrix, images.T)
    assert np.allclose(cells, np.rint(cells), atol=1e-9)
    across = np.any(images != 0.0, axis=1)
    assert 0 < across.sum() < len(pairs)
    strain_entries = lp.matrix[:, n * d:n * d + k].tocsr()
    assert np.all(np.diff(strain_entries.indptr)[~across] == 0)


@pytest.mark.parametrize("make", [lambda: lattices.triangular(4), lambda: lattices.fcc(2)],
                         ids=["triangular", "fcc"])
def test_a_strictly_jammed_crystal_is_returned_unchanged(make):
    packing = make()
    result = jam(packing, box="deformable")
    assert_strictly_jammed(result)
    assert result.phi == pytest.approx(packing.phi, abs=1e-9)
    assert result.iterations == 1
    assert np.allclose(result.packing.lattice, np.diag(packing.box), atol=1e-9)
    assert result.stress_anisotropy <= ISOTROPY_TOLERANCE


def test_kagome_moves_on_to_a_denser_strictly_jammed_packing():
    packing = lattices.kagome(2)
    assert jamming_category(packing, up_to="strict").category != "strict"
    result = jam(packing, box="deformable")
    assert_strictly_jammed(result)
    assert result.phi > packing.phi + 0.1
    assert jamming_category(result).category == "strict"


@pytest.mark.parametrize("d, n", [(2, 64), (3, 128)])
def test_a_random_packing_ends_strictly_jammed(d, n):
    import generators

    sizes = (generators.diameters.bidisperse(n) if d == 2
             else generators.diameters.monodisperse(n))
    start = generators.lubachevsky_stillinger(sizes, d=d, target_pressure=1e5,
                                              seed=0).packing
    fixed = jam(start)
    assert jamming_category(fixed).category == "collective"   # isostatic: never strict
    assert floppy_strict_rows(fixed.packing, *fixed.contacts.T, fixed.rattlers,
                              fixed.wall_contacts)
    result = jam(start, box="deformable")
    assert_strictly_jammed(result)
    assert result.isostatic and result.isostaticity_gap == 0
    assert result.phi > fixed.phi
    assert result.packing.is_sheared
    assert jamming_category(result).category == "strict"


def test_a_deformable_result_round_trips_and_jams_again_unchanged(tmp_path):
    start = ls_packing(64, 2, seed=1, pressure=1e5)
    result = jam(start, box="deformable")
    back = type(result).from_arrays(np.load(result.save(tmp_path / "r.npz")))
    assert back.box_mode == "deformable" and back.isostatic == result.isostatic
    assert np.array_equal(back.stress, result.stress)
    assert np.array_equal(back.packing.box_matrix, result.packing.box_matrix)
    again = jam(back.packing, box="deformable")
    assert again.phi == pytest.approx(result.phi, abs=1e-9)
    assert "box = deformable" in result.summary()


def test_deformable_box_refuses_what_it_does_not_run(tmp_path):
    packing = lattices.triangular(4)
    with pytest.raises(ValueError, match="LP route"):
        jam(packing, box="deformable", route="relaxed")
    with pytest.raises(ValueError, match="unknown box 'elastic'"):
        jam(packing, box="elastic")
    walled = Packing(packing.positions + [0.5, 0.5], packing.diameters,
                     packing.box + [1.0, 1.0], Boundaries.walls(2, ["x", "y"]))
    with pytest.raises(ValueError, match="needs a periodic axis"):
        jam(walled, box="deformable")


def test_cli_box_deformable_writes_the_box_and_the_stress(tmp_path):
    import json

    from click.testing import CliRunner

    from calippso.cli import cli

    source = write(lattices.kagome(2), tmp_path / "kagome.npz")
    run = CliRunner().invoke(cli, ["jam", str(source), "-o", str(tmp_path / "out.npz"),
                                   "--box", "deformable", "--json"])
    assert run.exit_code == 0, run.output
    record = json.loads(run.stdout)
    assert record["box"] == "deformable" and record["converged"]
    assert record["stress_anisotropy"] <= ISOTROPY_TOLERANCE
    assert np.allclose(record["box_matrix"], read(tmp_path / "out.npz").lattice)


# ------------------------------------------------------------------ the strict Newton stage

@pytest.fixture(scope="module")
def binary_spheres():
    """An LS packing of 96 spheres of two sizes (d = 3) and its deformable run by LPs alone."""
    import generators

    start = generators.lubachevsky_stillinger(generators.diameters.bidisperse(96), d=3,
                                              target_pressure=1e5, seed=1).packing
    return start, jam(start, box="deformable", newton=False)


def test_strict_newton_finds_the_jammed_point_of_a_perturbed_strict_network(binary_spheres):
    from calippso.certification.strict_newton import refine_strict

    jammed = binary_spheres[1]
    assert_strictly_jammed(jammed)
    assert jammed.isostaticity_gap == 0
    packing, (i, j) = jammed.packing, jammed.contacts.T
    rng = np.random.default_rng(0)
    shear = 1e-6 * rng.standard_normal((3, 3))
    deformation = np.eye(3) + 0.5 * (shear + shear.T)
    positions = packing.positions @ deformation.T + 1e-6 * rng.standard_normal((packing.n, 3))
    matrix = deformation @ packing.lattice
    vectors = Packing.sheared(positions, packing.diameters, matrix).minimum_image(
        positions[i] - positions[j])
    refined = refine_strict(positions, packing.diameters, matrix, i, j, vectors,
                            ~jammed.rattlers)
    assert refined is not None and refined.positive
    back = Packing.sheared(refined.positions, refined.diameters, refined.matrix)
    assert back.phi == pytest.approx(jammed.phi, abs=1e-9)
    assert np.allclose(refined.forces / refined.forces.mean(), jammed.forces, atol=1e-6)
    assert refine_strict(positions, packing.diameters, matrix, i[1:], j[1:], vectors[1:],
                         ~jammed.rattlers) is None      # one contact short: not square


def test_a_strict_network_read_from_an_lp_is_solved_by_newton_and_certified(binary_spheres):
    start, lps_only = binary_spheres
    result = jam(start, box="deformable")
    assert_strictly_jammed(result)
    assert result.isostatic and result.isostaticity_gap == 0
    assert result.history["stage"][-1] == "newton"
    assert result.stop_reason == StopReason.CERTIFIED_NEWTON
    assert lps_only.stop_reason == StopReason.CONVERGED
    assert result.iterations < lps_only.iterations
    assert result.phi == pytest.approx(lps_only.phi, abs=1e-9)
    assert result.phi > jam(start).phi
    assert jamming_category(result).category == "strict"


def test_rattlers_overlapped_by_the_newton_move_are_moved_out_and_others_refused():
    from calippso.certification.strict_newton import clear_rattlers
    from calippso.geometry.sheared_search import sheared_pairs_within

    packing = lattices.triangular(4)
    positions, diameters, matrix = packing.positions.copy(), packing.diameters, packing.lattice
    touching = sheared_pairs_within(positions, diameters, matrix, 1.0 + 1e-9)
    rattlers = np.zeros(packing.n, bool)
    rattlers[0] = True                      # its six pairs are no contacts
    keep = ~(rattlers[touching.i] | rattlers[touching.j])
    keys = np.sort(np.minimum(touching.i, touching.j)[keep] * packing.n
                   + np.maximum(touching.i, touching.j)[keep])
    pushed = positions.copy()
    pushed[0] += 3e-11 * touching.vectors[touching.i == 0][0] if np.any(touching.i == 0) \
        else -3e-11 * touching.vectors[touching.j == 0][0]
    cleared, stable_overlap = clear_rattlers(pushed, diameters, matrix, keys, rattlers,
                                             1e-12)
    assert cleared is not None and not stable_overlap
    gaps = sheared_pairs_within(cleared, diameters, matrix, 1.0 + 1e-6).gaps
    assert gaps.min() >= -1e-12
    moved = packing.minimum_image(cleared - pushed)
    assert np.abs(moved).max() < 1e-9 and np.abs(moved[1:]).max() < 1e-15
    squeezed = positions.copy()
    squeezed[1] += 3e-11 * (positions[2] - positions[1])    # two stable discs, no contact
    assert clear_rattlers(squeezed, diameters, matrix, keys[:0], rattlers,
                          1e-12) == (None, True)
