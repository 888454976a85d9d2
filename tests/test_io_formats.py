"""Round trips of every file format, format limits, and third-party readers of our files."""

from __future__ import annotations

import numpy as np
import pytest

import calippso
from calippso import Packing
from calippso.io import read_result

SUFFIXES_ANY_D = [".npz", ".h5", ".dat"]
SUFFIXES_3D = [".xyz", ".gsd"]


def _packing(d: int, n: int = 40, seed: int = 0, polydisperse: bool = True) -> Packing:
    rng = np.random.default_rng(seed)
    diameters = 0.5 + rng.random(n) if polydisperse else np.ones(n)
    return Packing(rng.random((n, d)) * 10 - 3, diameters, np.linspace(10, 12, d))


def _result(packing: Packing):
    from calippso.result import JammingResult, empty_history

    rattlers = np.zeros(packing.n, dtype=bool)
    rattlers[:3] = True
    return JammingResult(
        packing=packing,
        contacts=np.array([[3, 4], [4, 5]]),
        forces=np.array([0.5, 1.5]),
        rattlers=rattlers,
        converged=True,
        status="Converged after 1 LP.",
        iterations=1,
        history=empty_history(),
        wall_time=0.1,
        force_balance=1e-12,
        dual_normalization=1.0,
        solver="highs",
    )


def _assert_same(back: Packing, packing: Packing) -> None:
    """Same particles (any order, positions wrapped into the box), bit for bit."""
    wrapped, back = packing.wrapped(), back.wrapped()
    order, order_back = np.lexsort(wrapped.positions.T), np.lexsort(back.positions.T)
    np.testing.assert_array_equal(back.positions[order_back], wrapped.positions[order])
    np.testing.assert_array_equal(back.diameters[order_back], wrapped.diameters[order])
    np.testing.assert_array_equal(back.box, packing.box)


@pytest.mark.parametrize("suffix", SUFFIXES_ANY_D + SUFFIXES_3D + [".xyzd"])
@pytest.mark.parametrize("d", [2, 3, 4])
def test_round_trip_or_clear_refusal(tmp_path, suffix, d):
    if suffix == ".h5":
        pytest.importorskip("h5py")
    if suffix == ".gsd":
        pytest.importorskip("gsd")
    packing = _packing(d)
    path = tmp_path / f"packing{suffix}"
    holds = (
        suffix in SUFFIXES_ANY_D
        or (suffix in SUFFIXES_3D and d <= 3)
        or (suffix == ".xyzd" and d == 3)
    )
    if not holds:
        with pytest.raises(ValueError, match=f"d = {d}"):
            calippso.write(packing, path)
        assert not path.exists()
        return
    written = calippso.write(packing, path)
    back = calippso.read(written)
    if suffix == ".xyzd":  # diameters pass through the porosity ratio of packing.nfo
        np.testing.assert_allclose(back.diameters, packing.diameters, rtol=1e-15)
        np.testing.assert_array_equal(back.positions, packing.wrapped().positions)
    else:
        _assert_same(back, packing)


@pytest.mark.parametrize("suffix", [".npz", ".h5"])
def test_full_result_round_trip(tmp_path, suffix):
    if suffix == ".h5":
        pytest.importorskip("h5py")
    result = _result(_packing(5))
    back = read_result(calippso.write(result, tmp_path / f"result{suffix}"))
    _assert_same(back.packing, result.packing)
    np.testing.assert_array_equal(back.contacts, result.contacts)
    np.testing.assert_array_equal(back.forces, result.forces)
    np.testing.assert_array_equal(back.rattlers, result.rattlers)
    assert (back.status, back.solver, back.converged, back.iterations) == (
        result.status,
        result.solver,
        True,
        1,
    )


def test_read_result_refuses_a_bare_packing(tmp_path):
    path = calippso.write(_packing(3), tmp_path / "packing.npz")
    with pytest.raises(ValueError, match="missing keys"):
        read_result(path)
    with pytest.raises(ValueError, match="results are stored as"):
        read_result(calippso.write(_packing(3), tmp_path / "packing.xyz"))


@pytest.mark.parametrize("suffix", [".xyz", ".gsd"])
def test_viewer_formats_mark_rattlers(tmp_path, suffix):
    if suffix == ".gsd":
        gsd_hoomd = pytest.importorskip("gsd.hoomd")
    result = _result(_packing(3))
    path = calippso.write(result, tmp_path / f"result{suffix}")
    _assert_same(calippso.read(path), result.packing)
    if suffix == ".xyz":
        header = path.read_text().splitlines()[1]
        assert "rattler:L:1:contacts:I:1" in header
    else:
        with gsd_hoomd.open(path, "r") as trajectory:
            frame = trajectory[0]
        assert list(frame.particles.typeid[:4]) == [1, 1, 1, 0]
        centred = frame.particles.position[:, :3]
        assert np.all(np.abs(centred) <= 0.5 * result.packing.box + 1e-5)


def test_extxyz_is_read_by_ase(tmp_path):
    ase_io = pytest.importorskip("ase.io")
    packing = _packing(3)
    atoms = ase_io.read(calippso.write(packing, tmp_path / "packing.xyz"), format="extxyz")
    assert len(atoms) == packing.n and all(atoms.pbc)
    np.testing.assert_allclose(np.diag(atoms.cell[:]), packing.box)
    np.testing.assert_allclose(atoms.positions, packing.wrapped().positions)
    np.testing.assert_allclose(atoms.arrays["diameter"], packing.diameters)


def test_extxyz_written_by_ase_with_radius(tmp_path):
    ase = pytest.importorskip("ase")
    ase_io = pytest.importorskip("ase.io")

    packing = _packing(3)
    atoms = ase.Atoms(
        "H" * packing.n, positions=packing.positions, cell=np.diag(packing.box), pbc=True
    )
    atoms.new_array("radius", packing.diameters / 2)
    ase_io.write(tmp_path / "ase.xyz", atoms, format="extxyz")
    back = calippso.read(tmp_path / "ase.xyz")
    np.testing.assert_allclose(back.diameters, packing.diameters, atol=1e-8)  # ASE: 8 decimals
    np.testing.assert_allclose(back.box, packing.box)


def test_gsd_from_another_program_uses_float32_schema(tmp_path):
    gsd_hoomd = pytest.importorskip("gsd.hoomd")
    frame = gsd_hoomd.Frame()
    frame.configuration.box = [4.0, 5.0, 0.0, 0.0, 0.0, 0.0]
    frame.configuration.dimensions = 2
    frame.particles.N = 2
    frame.particles.position = np.array([[-1.0, -2.0, 0.0], [1.0, 2.0, 0.0]], dtype=np.float32)
    frame.particles.diameter = np.array([1.0, 0.5], dtype=np.float32)
    with gsd_hoomd.open(tmp_path / "hoomd.gsd", "w") as trajectory:
        trajectory.append(frame)
    packing = calippso.read(tmp_path / "hoomd.gsd")
    assert packing.d == 2
    np.testing.assert_allclose(packing.positions, [[1.0, 0.5], [3.0, 4.5]])
    np.testing.assert_allclose(packing.diameters, [1.0, 0.5])


@pytest.mark.parametrize(
    "text, message",
    [
        ("2\nnot a header\nX 0 0 0 1\nX 1 1 1 1\n", "no Lattice"),
        ('1\nLattice="5 0 0 0 5 0 0 0 5" Properties=species:S:1:pos:R:3\nX 0 0 0\n', "no diameter"),
        (
            '1\nLattice="5 1 0 0 5 0 0 0 5" Properties=species:S:1:pos:R:3:diameter:R:1\nX 0 0 0 1\n',
            "rectangular",
        ),
        (
            '2\nLattice="5 0 0 0 5 0 0 0 5" Properties=species:S:1:pos:R:3:diameter:R:1\nX 0 0 0 1\n',
            "truncated",
        ),
        (
            '1\nLattice="5 0 0 0 5 0 0 0 5" Properties=species:S:1:pos:R:3:diameter:R:1\nX 0 0 1\n',
            "fields where Properties",
        ),
        ("many\n", "line 1"),
    ],
)
def test_malformed_extxyz_is_named(tmp_path, text, message):
    path = tmp_path / "bad.xyz"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        calippso.read(path)


def test_unreadable_binary_files_are_named(tmp_path):
    pytest.importorskip("gsd")
    pytest.importorskip("h5py")
    for name in ("bad.gsd", "bad.h5"):
        (tmp_path / name).write_text("not binary data")
        with pytest.raises(ValueError, match="not a readable"):
            calippso.read(tmp_path / name)


def test_unknown_extension(tmp_path):
    with pytest.raises(ValueError, match="unknown output format '.pdb'"):
        calippso.write(_packing(3), tmp_path / "p.pdb")
