"""The sheared periodic box (a general box matrix) and the deformable box of `jam`."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from calippso import Packing
from calippso.io import read, write
from calippso.periodic import (lattice_minimum_image, lattice_wrap, reduce_lattice,
                               shortest_lattice_vector, triangular_box)


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
