"""Reports of packings with walls: the layering profile, the wall forces kept apart from the
particle forces, and the walls in the pictures."""

from __future__ import annotations

import json

import numpy as np
import pytest

import calippso
import generators
from calippso import Boundaries, Packing
from calippso.analysis import analyze, density_profile, pooled_density_profile
from calippso.analysis.slices import fraction_below, volume_inside_cylinder
from calippso.geometry.neighbors import contact_shrink
from calippso.geometry.packing import ball_volume

#: A bulk random jammed packing of equal spheres: φ ≈ 0.64; the middle of the slab below
#: (2 to 3.5 diameters from the walls) must lie within this band of it.
BULK_PHI, BULK_BAND = 0.64, 0.06
#: At the wall a sphere touches the plane at one point: the first bin (0.1 diameter) holds
#: little volume.
WALL_BIN_PHI = 0.2


@pytest.fixture(scope="module")
def slab():
    """N = 96 equal spheres jammed between walls at x = 0 and x = L_x, periodic in y, z,
    with L_x twice the other sides (about 7 diameters once jammed): random centres shrunk
    to no overlap, then `calippso.jam` (about 4 s)."""
    n, rng = 96, np.random.default_rng(1)
    box = np.array([2.0, 1.0, 1.0]) * (n * ball_volume(3, 0.5) / 0.3 / 2) ** (1 / 3)
    positions = rng.uniform(0.0, 1.0, (n, 3)) * box
    positions[:, 0] = 0.5 + rng.uniform(0.0, 1.0, n) * (box[0] - 1.0)
    points = Packing(positions, np.ones(n), box, Boundaries.walls(3, ["x"]))
    shrink = contact_shrink(points.positions, points.diameters, points.box)
    result = calippso.jam(points.scaled_to_phi(points.phi * shrink ** 3))
    assert result.isostatic and result.n_wall_contacts > 0
    return result


def test_a_plane_cuts_a_ball_as_the_cap_volume_says():
    # d = 3: the cap of height h = r (1 − u) holds π h² (3r − h)/3 of the volume 4π r³/3
    u = np.linspace(-1, 1, 9)
    h = 1.0 - u
    cap_above = np.pi * h ** 2 * (3 - h) / 3 / (4 * np.pi / 3)
    assert np.allclose(fraction_below(u, 3), 1.0 - cap_above, atol=1e-14)
    assert np.array_equal(fraction_below(np.array([-3.0, 3.0]), 4), [0.0, 1.0])


@pytest.mark.parametrize("d", [2, 3, 4])
def test_a_cylinder_holds_a_ball_whole_or_half(d):
    whole = volume_inside_cylinder(np.array([0.3]), np.array([0.5]), np.array([1.0]), d)
    # a ball centred on the cylinder's wall, of radius far below the cylinder's: about half
    half = volume_inside_cylinder(np.array([100.0]), np.array([0.5]), np.array([100.0]), d)
    assert whole[0, 0] == pytest.approx(ball_volume(d, 0.5), rel=1e-12)
    assert half[0, 0] == pytest.approx(ball_volume(d, 0.5) / 2, rel=1e-2)


@pytest.mark.parametrize("boundaries", [Boundaries.walls(3, ["x"]), Boundaries.walls(3, ["x", "y"]),
                                        Boundaries.cylinder(3, ["x", "y"]),
                                        Boundaries.walls(2, ["y"])],
                         ids=str)
def test_the_profile_averages_to_the_packing_fraction(boundaries):
    """Shell volumes times the profile add up to the volume of the spheres: its mean over
    the shells is φ."""
    points = generators.poisson(np.ones(400), boundaries.d, phi=0.3, seed=3,
                                boundaries=boundaries)
    profile = density_profile(points, bins=25)
    scale = points.mean_diameter
    width = (profile.distance[1] - profile.distance[0]) * scale
    outer, inner = profile.distance * scale + width / 2, profile.distance * scale - width / 2
    if boundaries.cylinder_axes:
        radius = points.box[0] / 2
        shells = (radius - inner) ** 2 - (radius - outer) ** 2
    else:
        shells = np.full(profile.phi.size, width)
    assert np.sum(profile.phi * shells) / np.sum(shells) == pytest.approx(points.phi, rel=1e-9)


def test_an_ideal_gas_is_flat_beyond_one_diameter_from_the_wall():
    """Centres uniform in [σ/2, L − σ/2]: beyond one diameter the profile is their density
    times the sphere volume, N V / ((L − σ) A)."""
    points = generators.poisson(np.ones(20000), 3, phi=0.3, seed=1,
                                boundaries=Boundaries.walls(3, ["x"]))
    profile = density_profile(points, axis="x", bins=np.arange(0.0, 8.01, 0.5))
    side = points.box[0]
    expected = points.phi * side / (side - 1.0)
    flat = profile.phi[profile.distance > 1.5]          # each bin holds some 600 spheres
    assert np.mean(flat) == pytest.approx(expected, rel=0.03)
    assert np.allclose(flat, expected, rtol=0.15)
    assert profile.phi[0] < 0.5 * expected                   # half a diameter at the wall


def test_a_jammed_slab_is_layered_and_bulk_in_its_middle(slab):
    half = slab.packing.box[0] / 2 / slab.packing.mean_diameter
    profile = density_profile(slab, bins=np.arange(0.0, half, 0.1))
    middle = profile.phi[profile.distance > 2.0]
    assert abs(np.mean(middle) - BULK_PHI) < BULK_BAND
    assert profile.phi[0] < WALL_BIN_PHI
    # the first layer: denser than the bulk, half a diameter from the wall
    first_layer = profile.phi[(profile.distance > 0.3) & (profile.distance < 0.8)]
    assert first_layer.max() > np.mean(middle)


def test_the_profile_refuses_a_periodic_packing_and_an_axis_without_walls(slab):
    with pytest.raises(ValueError, match="no walls"):
        density_profile(Packing(slab.packing.positions, slab.packing.diameters,
                                slab.packing.box))
    with pytest.raises(ValueError, match="has no wall"):
        density_profile(slab, axis="y")


def test_the_analysis_keeps_wall_forces_apart(slab):
    analysis = analyze(slab)
    pair = np.sort(slab.forces / slab.forces.mean())
    assert np.array_equal(analysis.forces["all"].values, pair)        # no wall force in it
    assert len(analysis.wall_forces) == slab.n_wall_contacts
    assert np.allclose(analysis.wall_forces.values,
                       np.sort(slab.wall_forces) / slab.forces.mean(), rtol=1e-14)
    low, high = analysis.wall_loads
    assert (low["wall"], high["wall"]) == ("x = 0", "x = L")
    assert low["contacts"] + high["contacts"] == slab.n_wall_contacts
    assert low["contacts"] > 0 and high["contacts"] > 0
    assert low["load"] == pytest.approx(-high["load"], rel=1e-10) and high["load"] > 0
    assert low["pressure"] == pytest.approx(high["pressure"], rel=1e-10)
    profile = pooled_density_profile([slab])
    assert np.allclose(profile.phi, analysis.layering.phi)


def test_the_report_has_a_walls_section_and_figure(slab, tmp_path):
    pytest.importorskip("matplotlib")
    page = calippso.report(slab, tmp_path, n_bootstrap=10)
    summary = json.loads((tmp_path / "summary.json").read_text())
    walls = summary["walls"]
    assert walls["wall_forces"]["count"] == slab.n_wall_contacts
    assert summary["localized_forces"] + summary["extended_forces"] == slab.forces.size
    assert walls["loads"][1]["load"] == pytest.approx(slab.wall_loads[0, 1])
    assert "| 0 | x = L |" in page.read_text()
    assert summary["figures"]["walls"] == "walls.png" and (tmp_path / "walls.png").stat().st_size
    text = page.read_text()
    assert "## Walls" in text and "![walls](walls.png)" in text


def test_a_periodic_analysis_has_no_walls_entry(slab):
    """The slab's network in a periodic box (no wall contact): nothing about walls."""
    import dataclasses

    periodic = Packing(slab.packing.positions, slab.packing.diameters, slab.packing.box)
    result = dataclasses.replace(slab, packing=periodic, wall_contacts=np.zeros((0, 2), int),
                                 wall_forces=np.zeros(0))
    analysis = analyze(result)
    assert analysis.layering is None and analysis.wall_forces is None
    assert "walls" not in analysis.to_dict()


def _wall_lines(figure):
    from matplotlib.collections import LineCollection

    from calippso.reporting.containers import WALL_COLOUR

    return [c for c in figure.axes[0].collections if isinstance(c, LineCollection)
            and np.allclose(c.get_colors()[0][:3], WALL_COLOUR)]


def test_pictures_draw_the_walls(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    from calippso.reporting import render as frame

    figures = []
    save = frame.save_figure
    monkeypatch.setattr(frame, "save_figure",
                        lambda figure, path: figures.append(figure) or save(figure, path))
    discs = generators.poisson(np.ones(30), 2, phi=0.1, seed=2,
                               boundaries=Boundaries.walls(2, ["y"]))
    frame.render_spheres(discs, tmp_path / "walls.png", backend="matplotlib", size=200)
    (lines,) = _wall_lines(figures[-1])
    segments = np.array(lines.get_segments())
    assert segments.shape == (2, 2, 2)                       # y = 0 and y = L, across x
    assert np.allclose(np.sort(segments[:, 0, 1]), [0.0, discs.box[1]])
    in_disc = generators.poisson(np.ones(30), 2, phi=0.1, seed=2,
                                 boundaries=Boundaries.cylinder(2, ["x", "y"]))
    frame.render_spheres(in_disc, tmp_path / "disc.png", backend="matplotlib", size=200)
    (circle,) = _wall_lines(figures[-1])
    ends = np.array(circle.get_segments())[:, 0]
    radius = np.hypot(*(ends - in_disc.box / 2).T)
    assert np.allclose(radius, in_disc.box[0] / 2)
    legend = [t.get_text() for t in figures[-1].legends[0].get_texts()]
    assert "cylinder in x, y" in legend
    spheres = generators.poisson(np.ones(30), 3, phi=0.1, seed=2,
                                 boundaries=Boundaries.walls(3, ["x", "y"]))
    frame.render_spheres(spheres, tmp_path / "spheres.png", backend="matplotlib", size=200)
    assert len(_wall_lines(figures[-1])) == 4                # the outlines of four faces


@pytest.mark.slow
def test_the_walls_example_prints_a_layered_profile(tmp_path, monkeypatch, capsys):
    """examples/walls_layering.py --tiny: isostatic in its cylinder, sparse at the wall, the
    picture written (the tests/test_examples.py case runs it too)."""
    pytest.importorskip("matplotlib")
    import runpy
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "examples" / "walls_layering.py"
    monkeypatch.chdir(tmp_path)
    runpy.run_path(str(script), run_name="example_walls_layering")["main"](
        ["--tiny", "--picture", "--out", str(tmp_path)])
    output = capsys.readouterr().out
    assert "(isostatic)" in output and "cylinder in x, y" in output
    first = next(line for line in output.splitlines() if line.startswith("   0.12"))
    assert float(first.split()[1]) < 2 * WALL_BIN_PHI       # a quarter-diameter bin at the wall
    assert (tmp_path / "layering.png").stat().st_size > 0


def test_povray_scenes_hold_the_walls():
    """A thin translucent slab outside each flat wall, an open cylinder of the box's radius."""
    from calippso.reporting.containers import povray_walls

    box = np.array([4.0, 5.0, 6.0])
    slabs = povray_walls(Packing([[2.0, 2.5, 3.0]], [1.0], box, Boundaries.walls(3, ["y"])))
    assert len(slabs) == 2 and all(line.startswith("box {") and "rgbt" in line
                                   for line in slabs)
    assert "<4.0, 0.0, 6.0>" in slabs[0] and "<0.0, 5.0, 0.0>" in slabs[1]    # y ≤ 0, y ≥ L
    square = np.array([4.0, 4.0, 6.0])
    (tube,) = povray_walls(Packing([[2.0, 2.0, 3.0]], [1.0], square,
                                   Boundaries.cylinder(3, ["x", "y"])))
    assert tube.startswith("cylinder { <2.0, 2.0, 0.0>, <2.0, 2.0, 6.0>, 2.0 open")
