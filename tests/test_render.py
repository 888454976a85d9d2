"""Pictures: spheres and disks (calippso.reporting.render) and spherocylinders, each with a
title, a colour key and the box outline; POV-Ray pictures framed the same way."""

from __future__ import annotations

import os
import stat
import sys

import numpy as np
import pytest

from calippso import Packing
from calippso.reporting import render as frame
from calippso.reporting.render import (RATTLER_COLOUR, SPECIES_COLOURS, box_edges,
                                       povray_scene, render_spheres, sphere_colours)

pytest.importorskip("matplotlib")


@pytest.fixture
def drawn(monkeypatch) -> list:
    """The figures the render functions save, in order (they are still saved)."""
    figures = []
    save = frame.save_figure

    def keep(figure, path):
        figures.append(figure)
        return save(figure, path)

    monkeypatch.setattr(frame, "save_figure", keep)
    return figures


def _bidisperse(d: int, n: int = 40, seed: int = 0) -> Packing:
    rng = np.random.default_rng(seed)
    return Packing(rng.random((n, d)) * 6, np.where(np.arange(n) % 2, 1.4, 1.0), 6.0)


def _texts(figure) -> tuple[list[str], list[str]]:
    """The figure's own texts (the title) and the labels of its colour key."""
    legend = figure.legends[0]
    return [t.get_text() for t in figure.texts], [t.get_text() for t in legend.get_texts()]


def _outline_segments(axis) -> int:
    """Box edges drawn: the segments of line collections, or 4 for a rectangle patch."""
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Rectangle

    lines = sum(len(c.get_segments()) for c in axis.collections
                if isinstance(c, LineCollection) and c.get_zorder() != 2)
    return lines + 4 * sum(isinstance(p, Rectangle) and not p.get_fill() for p in axis.patches)


def test_box_edges_are_the_twelve_edges_of_the_box():
    box = np.array([1.0, 2.0, 3.0])
    edges = box_edges(box)
    lengths = np.linalg.norm(edges[:, 1] - edges[:, 0], axis=1)
    assert edges.shape == (12, 2, 3) and sorted(lengths) == [1.0] * 4 + [2.0] * 4 + [3.0] * 4
    assert edges.min() == 0.0 and np.all(edges.max(axis=(0, 1)) == box)


def test_sphere_colours_and_key():
    packing = _bidisperse(3)
    colours, key = sphere_colours(packing)
    assert [label for label, _ in key] == ["σ = 1", "σ = 1.4"]
    np.testing.assert_array_equal(colours[packing.diameters == 1.4], [SPECIES_COLOURS[1]] * 20)
    rattlers = np.zeros(packing.n, dtype=bool)
    rattlers[:3] = True
    colours, key = sphere_colours(packing, rattlers)
    assert key[-1] == ("rattler", RATTLER_COLOUR) and np.all(colours[:3] == RATTLER_COLOUR)
    rng = np.random.default_rng(1)
    polydisperse = Packing(rng.random((50, 3)) * 9, 0.5 + rng.random(50), 9.0)
    _, key = sphere_colours(polydisperse)
    assert [label for label, _ in key] == [
        f"σ = {v:.4g}" for v in np.quantile(polydisperse.diameters, [0, 0.5, 1])]


@pytest.mark.parametrize("d, kind, edges", [(2, "disks", 4), (3, "spheres", 12)])
def test_sphere_picture_has_title_key_and_box_outline(tmp_path, drawn, d, kind, edges):
    import matplotlib.image

    packing = _bidisperse(d)
    rattlers = np.arange(packing.n) < 2
    path = render_spheres(packing, tmp_path / "p.png", rattlers=rattlers, size=240,
                          backend="matplotlib")
    assert matplotlib.image.imread(path).shape[:2] == (240, 240)
    title, key = _texts(drawn[0])
    assert title == [f"40 {kind}, d = {d}, φ = {packing.phi:.4f}, 2 rattlers"]
    assert key == ["σ = 1", "σ = 1.4", "rattler"]
    assert _outline_segments(drawn[0].axes[0]) == edges


def test_sphere_picture_refusals(tmp_path):
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="d = 2 or 3, this one has d = 4"):
        render_spheres(Packing(rng.random((9, 4)) * 5, np.ones(9), 5.0), tmp_path / "x.png")
    with pytest.raises(ValueError, match="POV-Ray draws d = 3 pictures"):
        render_spheres(_bidisperse(2), tmp_path / "x.png", backend="povray")
    with pytest.raises(ValueError, match="backend must be one of"):
        render_spheres(_bidisperse(3), tmp_path / "x.png", backend="vtk")


@pytest.mark.parametrize("colour_by, key", [
    ("orientation", ["axis ∥ x", "axis ∥ y", "axis ∥ z"]),
    ("species", ["d = 1, l = 1", "d = 1, l = 2"])])
def test_spherocylinder_picture_has_title_key_and_box_outline(tmp_path, drawn, colour_by,
                                                              key):
    from generators.spherocylinders import SpherocylinderPacking, render

    rng = np.random.default_rng(2)
    axes = rng.normal(size=(30, 3))
    packing = SpherocylinderPacking(rng.random((30, 3)) * 8, axes / np.linalg.norm(
        axes, axis=1)[:, None], np.ones(30), np.where(np.arange(30) % 3, 1.0, 2.0),
        np.full(3, 8.0))
    render(packing, tmp_path / "rods.png", backend="matplotlib", size=200, colour_by=colour_by)
    title, labels = _texts(drawn[0])
    assert title == [f"30 spherocylinders, φ = {packing.phi:.4f}, nematic order S = "
                     f"{packing.nematic_order():.3f}"]
    assert labels == key
    assert _outline_segments(drawn[0].axes[0]) == 12


def test_povray_scene_draws_the_box_edges():
    lines = povray_scene(np.array([2.0, 3.0, 4.0]), 25.0, 35.0)
    edges = [line for line in lines if line.startswith("cylinder")]
    assert len(edges) == 12 and "<2.0, 3.0, 4.0>" in "".join(edges)


@pytest.fixture
def fake_povray(tmp_path, monkeypatch):
    """A `povray` program on the PATH that writes a grey square of the asked size."""
    folder = tmp_path / "bin"
    folder.mkdir()
    program = folder / "povray"
    program.write_text(
        f"#!{sys.executable}\n"
        "import sys, numpy, matplotlib.image\n"
        "args = {a[:2]: a[2:] for a in sys.argv[1:] if a[:2] in ('+O', '+W')}\n"
        "side = int(next(a[2:] for a in sys.argv[1:] if a[:2] == '+W' and a[2:].isdigit()))\n"
        "matplotlib.image.imsave(args['+O'], numpy.full((side, side, 3), 0.5))\n")
    program.chmod(program.stat().st_mode | stat.S_IXUSR)
    monkeypatch.setenv("PATH", f"{folder}{os.pathsep}{os.environ['PATH']}")


def test_povray_pictures_are_framed_with_title_and_key(tmp_path, drawn, fake_povray):
    packing = _bidisperse(3)
    path = render_spheres(packing, tmp_path / "p.png", size=150)  # "auto" takes POV-Ray
    title, key = _texts(drawn[0])
    assert title == [f"40 spheres, d = 3, φ = {packing.phi:.4f}"]
    assert key == ["σ = 1", "σ = 1.4"] and path.read_bytes()[:4] == b"\x89PNG"


def test_sphere_pictures_never_load_numba(tmp_path):
    import subprocess

    code = ("import sys, numpy as np; from calippso import Packing; "
            "from calippso.reporting.render import render_spheres; "
            f"render_spheres(Packing(np.ones((1, 3)), [1.0], 4.0), {str(tmp_path / 'p.png')!r}, "
            "backend='matplotlib', size=64); print('numba' in sys.modules)")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert run.stdout.strip() == "False"
