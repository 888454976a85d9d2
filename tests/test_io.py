import numpy as np
import pytest

import calippso
from calippso import Packing
from calippso.geometry.neighbors import min_gap

# (name, N, phi from the data README after the .nfo rescale)
SHARED = [
    ("mono_N1000_fba1e-3_then_ls1e-2_seed11", 1000, 0.631710),
    ("mono_N10000_fba1e-3_then_ls1e-2_seed21", 10000, 0.634564),
    ("lognormal0.2_N1000_fba1e-3_then_ls1e-2_seed13", 1000, 0.647250),
    ("mono_N1000_fba1e-3_phinom0.6_seed11", 1000, 0.596552),
    ("skoge_donev_N1000_d3_p1e12.dat", 1000, 0.638386),
]


@pytest.mark.parametrize("name, n, phi", SHARED)
def test_reads_shared_packings(shared_data, name, n, phi):
    packing = calippso.read(shared_data / name)
    assert packing.n == n and packing.d == 3
    assert packing.phi == pytest.approx(phi, abs=5e-7)
    gap, _ = min_gap(packing.positions, packing.diameters, packing.box)
    assert gap > -1e-14  # only round-off overlaps in these inputs


def test_xyzd_path_equals_folder(shared_data):
    folder = shared_data / "lognormal0.2_N1000_fba1e-3_then_ls1e-2_seed13"
    a, b = calippso.read(folder), calippso.read(folder / "packing.xyzd")
    np.testing.assert_array_equal(a.diameters, b.diameters)


def _random_packing(d, n=30, seed=0):
    rng = np.random.default_rng(seed)
    return Packing(rng.random((n, d)) * 10, 0.5 + rng.random(n), np.linspace(10, 12, d))


@pytest.mark.parametrize("suffix", [".npz", ".dat"])
@pytest.mark.parametrize("d", [2, 3, 5])
def test_round_trip(tmp_path, suffix, d):
    packing = _random_packing(d)
    path = calippso.write(packing, tmp_path / f"p{suffix}")
    back = calippso.read(path)
    order = np.lexsort(packing.wrapped().positions.T)
    order_back = np.lexsort(back.positions.T)
    np.testing.assert_array_equal(back.positions[order_back], packing.wrapped().positions[order])
    np.testing.assert_array_equal(back.diameters[order_back], packing.diameters[order])
    np.testing.assert_array_equal(back.box, packing.box)


def test_round_trip_packing_generation(tmp_path):
    packing = _random_packing(3)
    calippso.write(packing, tmp_path / "pg" / "packing.xyzd")
    back = calippso.read(tmp_path / "pg")
    np.testing.assert_allclose(back.diameters, packing.diameters, rtol=1e-15)
    np.testing.assert_array_equal(back.positions, packing.wrapped().positions)


def test_stripped_calippso_variant(tmp_path):
    path = tmp_path / "stripped.dat"
    path.write_text("2\n3\n0.1\n0.1 0.2\n0.5 0.5\n0.9 0.1\n")
    packing = calippso.read(path)
    assert packing.n == 3 and packing.d == 2
    np.testing.assert_array_equal(packing.box, [1.0, 1.0])
    np.testing.assert_array_equal(packing.diameters, [0.1] * 3)


@pytest.mark.parametrize(
    "content, message",
    [
        ("3\n1000 1\n1000\n0.1\n1 0 0 0 1 0 0 0 1\nT T T\n0.1 0.2 0.3\n", "truncated"),
        ("three\n10\n0.1\n0.1 0.2\n", "dimension"),
        ("2\n2\n0.1\n0.1 abc\n0.2 0.3\n", "non-numeric"),
    ],
)
def test_malformed_text_files(tmp_path, content, message):
    path = tmp_path / "bad.dat"
    path.write_text(content)
    with pytest.raises(ValueError, match=message):
        calippso.read(path)


def test_unknown_format_and_missing_file(tmp_path):
    (tmp_path / "a.xyz9").write_text("x")
    with pytest.raises(ValueError, match="unknown file format"):
        calippso.read(tmp_path / "a.xyz9")
    with pytest.raises(FileNotFoundError):
        calippso.read(tmp_path / "nothing.dat")


def test_binary_garbage_is_rejected(tmp_path):
    path = tmp_path / "garbage.dat"
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(ValueError):
        calippso.read(path)
