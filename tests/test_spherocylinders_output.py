"""Extended XYZ (OVITO) round trip and quaternions; PNG rendering (matplotlib; POV-Ray if any)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from generators.spherocylinders import SpherocylinderPacking, read_xyz, render, write_xyz
from generators.spherocylinders.xyz import axis_quaternions


def _packing(n=40, seed=0):
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    axes[0] = [0, 0, -1.0]  # the half-turn case of the quaternion
    axes[1] = [0, 0, 1.0]
    lengths = np.where(np.arange(n) % 2, 2.0, 0.0)  # rods and spheres (two species)
    return SpherocylinderPacking(rng.uniform(0, 10, (n, 3)), axes, np.ones(n), lengths, 10.0)


def _rotate(quaternion, vector):
    x, y, z, w = quaternion
    q = np.array([x, y, z])
    return vector + 2 * w * np.cross(q, vector) + 2 * np.cross(q, np.cross(q, vector))


def test_quaternions_turn_z_onto_the_axis():
    packing = _packing()
    quaternions = axis_quaternions(packing.axes)
    np.testing.assert_allclose(np.linalg.norm(quaternions, axis=1), 1.0, atol=1e-14)
    for quaternion, axis in zip(quaternions, packing.axes):
        np.testing.assert_allclose(_rotate(quaternion, np.array([0, 0, 1.0])), axis, atol=1e-12)


def test_xyz_round_trip(tmp_path):
    packing = _packing()
    path = write_xyz(packing, tmp_path / "packing.xyz", comment='made by "test"')
    lines = path.read_text().splitlines()
    assert lines[0] == str(packing.n)
    assert 'Lattice="10.0 0.0 0.0 0.0 10.0 0.0 0.0 0.0 10.0"' in lines[1]
    assert "orientation:R:4" in lines[1] and "aspherical_shape:R:3" in lines[1]
    assert {line.split()[0] for line in lines[2:]} == {"A", "B"}
    back = read_xyz(path)
    for name in ("positions", "axes", "diameters", "lengths", "box"):
        np.testing.assert_allclose(getattr(back, name), getattr(packing, name), rtol=0, atol=1e-15)
    # OVITO's spherocylinder shape: (radius, -, cylinder length).
    first = np.array(lines[2].split()[1:], dtype=float)
    np.testing.assert_allclose(first[7:10], [0.5, 0.5, packing.lengths[0]])


def test_render_matplotlib(tmp_path):
    path = render(_packing(), tmp_path / "picture.png", backend="matplotlib", size=200)
    import matplotlib.image

    image = matplotlib.image.imread(path)
    assert image.shape[:2] == (200, 200)
    assert np.mean(image[..., :3] < 0.9) > 0.05  # particles were drawn on the white page


def test_render_povray_if_installed(tmp_path):
    if shutil.which("povray") is None:
        pytest.skip("povray is not installed")
    path = render(_packing(), tmp_path / "picture.png", backend="povray", size=120)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_render_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="backend"):
        render(_packing(), tmp_path / "x.png", backend="vtk")
    with pytest.raises(ValueError, match="colour_by"):
        render(_packing(), tmp_path / "x.png", colour_by="size")
