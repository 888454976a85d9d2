"""Boundaries in files: every format that can hold flat walls keeps them, bit for bit; the
others refuse a box with walls in one line; PackingGeneration's rectangle mode is read."""

from __future__ import annotations

import numpy as np
import pytest

import calippso
from calippso import Boundaries, Packing
from calippso.io import read_result

from configurations import lognormal, random_sequential_addition


def _walled(d: int, axes, n: int = 40) -> Packing:
    return random_sequential_addition(n, d, 0.3, 4, lognormal(n, 0.2, 4),
                                      Boundaries.walls(d, axes))


CASES = [(2, [0]), (3, [2]), (3, [0, 1])]


@pytest.mark.parametrize("suffix", [".npz", ".h5", ".xyz", ".gsd", ".xyzd"])
@pytest.mark.parametrize("d, axes", CASES)
def test_walls_round_trip(tmp_path, suffix, d, axes):
    if suffix == ".h5":
        pytest.importorskip("h5py")
    if suffix == ".gsd":
        pytest.importorskip("gsd")
    packing = _walled(d, axes)
    path = tmp_path / f"packing{suffix}"
    if suffix == ".xyzd" and (d, axes) != (3, [0, 1]):
        why = "d = 3 only" if d != 3 else "PackingGeneration holds periodic boxes, cylinders"
        with pytest.raises(ValueError, match=why) as refused:
            calippso.write(packing, path)
        assert "\n" not in str(refused.value)
        return
    calippso.write(packing, path)
    back = calippso.read(path.parent / "packing.xyzd" if suffix == ".xyzd" else path)
    assert back.boundaries == packing.boundaries
    np.testing.assert_array_equal(back.box, packing.box)
    order = np.argsort(packing.diameters, kind="stable")
    back_order = np.argsort(back.diameters, kind="stable")
    np.testing.assert_array_equal(back.positions[back_order], packing.positions[order])
    np.testing.assert_array_equal(back.diameters[back_order], packing.diameters[order])


def test_periodic_files_carry_no_boundaries(tmp_path):
    packing = random_sequential_addition(20, 3, 0.2, 1)
    calippso.write(packing, tmp_path / "p.npz")
    assert "boundaries" not in np.load(tmp_path / "p.npz").files
    calippso.write(packing, tmp_path / "p.xyz")
    assert 'pbc="T T T"' in (tmp_path / "p.xyz").read_text().splitlines()[1]
    calippso.write(packing, tmp_path / "pg" / "packing.xyzd")
    assert "Boundaries mode: 1" in (tmp_path / "pg" / "generation.conf").read_text()


def test_extxyz_pbc_flags_are_the_walls(tmp_path):
    calippso.write(_walled(3, [2]), tmp_path / "z.xyz")
    header = (tmp_path / "z.xyz").read_text().splitlines()[1]
    assert 'pbc="T T F"' in header and "dimension=3" in header
    calippso.write(_walled(2, [0]), tmp_path / "x.xyz")
    assert 'pbc="F T F"' in (tmp_path / "x.xyz").read_text().splitlines()[1]
    # written by hand: walls in x and y, periodic z
    text = ('2\nLattice="4 0 0 0 4 0 0 0 5" Properties=species:S:1:pos:R:3:diameter:R:1 '
            'pbc="F F T"\nX 0.5 0.5 4.9 1\nX 2 3 1 1\n')
    (tmp_path / "hand.xyz").write_text(text)
    assert calippso.read(tmp_path / "hand.xyz").boundaries == Boundaries.walls(3, "x,y".split(","))


def test_a_particle_outside_the_walls_of_a_file_is_refused(tmp_path):
    text = ('2\nLattice="4 0 0 0 4 0 0 0 5" Properties=species:S:1:pos:R:3:diameter:R:1 '
            'pbc="F T T"\nX 0.2 0.5 4.9 1\nX 2 3 1 1\n')
    (tmp_path / "out.xyz").write_text(text)
    with pytest.raises(ValueError, match="out.xyz: 1 particle.* outside the container") as error:
        calippso.read(tmp_path / "out.xyz")
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("suffix", [".dat"])
def test_formats_without_walls_refuse_them(tmp_path, suffix):
    with pytest.raises(ValueError, match="Skoge-Donev files hold periodic packings") as error:
        calippso.write(_walled(3, [0]), tmp_path / f"p{suffix}")
    assert "\n" not in str(error.value)


def test_skoge_donev_non_periodic_flags_are_refused(tmp_path):
    packing = random_sequential_addition(10, 2, 0.2, 1)
    calippso.write(packing, tmp_path / "p.dat")
    lines = (tmp_path / "p.dat").read_text().splitlines()
    lines[5] = "T F"
    (tmp_path / "f.dat").write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"f.dat, line 6: periodicity flags 'T F'"):
        calippso.read(tmp_path / "f.dat")


@pytest.mark.parametrize("suffix", [".npz", ".h5"])
def test_result_with_wall_contacts_round_trip(tmp_path, suffix):
    if suffix == ".h5":
        pytest.importorskip("h5py")
    from calippso.result import JammingResult

    packing = _walled(3, [0, 1])
    result = JammingResult(packing=packing, contacts=np.array([[3, 4]]), forces=np.array([1.0]),
                           rattlers=np.zeros(packing.n, bool), converged=True, status="",
                           iterations=1, wall_contacts=np.array([[3, 0], [4, 1]]),
                           wall_forces=np.array([0.5, 1.5]))
    path = tmp_path / f"result{suffix}"
    calippso.write(result, path)
    back = read_result(path)
    assert back.packing.boundaries == packing.boundaries
    np.testing.assert_array_equal(back.wall_contacts, result.wall_contacts)
    np.testing.assert_array_equal(back.wall_forces, result.wall_forces)
    np.testing.assert_array_equal(back.wall_loads, result.wall_loads)
    assert back.n_contacts == 3
