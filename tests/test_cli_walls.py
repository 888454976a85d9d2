"""The `calippso` command with walls: ``--walls``/``--cylinder`` in generate, jam, report and
render, the boundaries kept in every file, and the one-line refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

import calippso
from calippso import Boundaries, Packing
from calippso.cli import main
from calippso.cli.common import Container, call_with_boundaries
from calippso.io import read_result

WALLS_X = Boundaries.walls(3, ["x"])


def _run(capfd, *argv) -> tuple[int, str, str]:
    code = main(list(map(str, argv)))
    captured = capfd.readouterr()
    return code, captured.out, captured.err


@pytest.fixture(scope="module")
def walled(tmp_path_factory):
    """A random start of N = 64 spheres between walls in x, and its jammed result, both made
    through the CLI (about 4 s); the JSON records of both commands."""
    folder = tmp_path_factory.mktemp("walls")
    start, jammed = folder / "start.npz", folder / "jammed.npz"
    records = []
    for argv in (["generate", "random", "--n", "64", "--d", "3", "--walls", "x", "--seed", "1",
                  "-o", start],
                 ["jam", start, "-o", jammed]):
        with pytest.MonkeyPatch.context() as patch:
            lines = []
            patch.setattr("click.echo", lambda text="", err=False, **_: lines.append(text))
            code = main([*map(str, argv), "--json", "--quiet"])
        assert code == 0, lines
        records.append(json.loads(lines[-1]))
    return start, jammed, records


def test_generate_and_jam_keep_the_walls(walled):
    start, jammed, (generated, jam_record) = walled
    packing = calippso.read(start)
    assert packing.boundaries == WALLS_X and generated["boundaries"] == str(WALLS_X)
    x = packing.positions[:, 0]
    assert np.all((x >= packing.diameters / 2) & (x <= packing.box[0] - packing.diameters / 2))
    result = read_result(jammed)
    assert result.packing.boundaries == WALLS_X
    assert jam_record["boundaries"] == str(WALLS_X) and jam_record["isostatic"]
    assert jam_record["n_wall_contacts"] == result.n_wall_contacts > 0
    # the walls hold the packing: the loads on the two walls balance
    assert result.wall_loads[0, 0] == pytest.approx(-result.wall_loads[0, 1], rel=1e-10)


@pytest.mark.slow
def test_report_keeps_wall_forces_out_of_the_particle_forces(walled, tmp_path, capfd,
                                                             monkeypatch):
    pytest.importorskip("matplotlib")
    import functools

    # 20 bootstrap resamples instead of 1000: the exponents are not what is tested here
    monkeypatch.setattr(calippso, "report", functools.partial(calippso.report, n_bootstrap=20))
    _, jammed, _ = walled
    code, _, err = _run(capfd, "report", jammed, "-o", tmp_path / "report", "--quiet")
    assert code == 0, err
    result = read_result(jammed)
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    assert summary["localized_forces"] + summary["extended_forces"] == result.forces.size
    assert summary["walls"]["wall_forces"]["count"] == result.n_wall_contacts
    assert [row["wall"] for row in summary["walls"]["loads"]] == ["x = 0", "x = L"]
    layering = summary["walls"]["layering"]
    assert layering["phi"][0] < 0.5 * result.phi              # next to the wall: sparse
    assert (tmp_path / "report" / "walls.png").is_file()


def test_render_draws_a_walled_packing(walled, tmp_path, capfd):
    pytest.importorskip("matplotlib")
    import matplotlib.image

    _, jammed, _ = walled
    code, out, err = _run(capfd, "render", jammed, "-o", tmp_path / "picture.png", "--size",
                          "300", "--backend", "matplotlib", "--json")
    assert code == 0, err
    assert json.loads(out)["boundaries"] == str(WALLS_X)
    assert matplotlib.image.imread(tmp_path / "picture.png").shape[:2] == (300, 300)


def test_the_options_set_the_boundaries_of_a_periodic_file(tmp_path, capfd):
    """A periodic file with every centre at least a radius from the planes x = 0 and L: render
    and jam give it walls in x."""
    rng = np.random.default_rng(4)
    positions = rng.uniform(0.0, 1.0, (24, 3)) * 5.0
    positions[:, 0] = 0.5 + rng.uniform(0.0, 1.0, 24) * 4.0
    calippso.write(Packing(positions, np.full(24, 0.3), 5.0), tmp_path / "periodic.npz")
    code, out, err = _run(capfd, "render", tmp_path / "periodic.npz", "--walls", "0", "-o",
                          tmp_path / "p.png", "--backend", "matplotlib", "--size", "200",
                          "--json")
    assert code == 0, err
    assert json.loads(out)["boundaries"] == str(WALLS_X)


def test_disagreeing_boundaries_are_refused_in_one_line(walled, tmp_path, capfd):
    start, _, _ = walled
    code, out, err = _run(capfd, "jam", start, "--cylinder", "x,y", "-o", tmp_path / "j.npz")
    assert code == 1 and out == ""
    assert err.count("\n") == 1 and str(start) in err and "walls in x" in err
    code, _, err = _run(capfd, "render", start, "--walls", "y", "-o", tmp_path / "p.png")
    assert code == 1 and str(start) in err and "--walls y" in err
    # the same boundaries again are accepted
    code, _, err = _run(capfd, "render", start, "--walls", "x", "-o", tmp_path / "p.png",
                        "--backend", "matplotlib", "--size", "200", "--quiet")
    assert code == 0, err


def test_a_periodic_file_crossing_the_new_walls_is_refused(tmp_path, capfd):
    positions = np.array([[0.05, 1.0, 1.0], [2.0, 2.0, 2.0]])
    calippso.write(Packing(positions, np.ones(2), 4.0), tmp_path / "edge.npz")
    code, _, err = _run(capfd, "render", tmp_path / "edge.npz", "--walls", "x", "-o",
                        tmp_path / "p.png")
    assert code == 1 and err.count("\n") == 1
    assert "edge.npz" in err and "outside the container" in err


@pytest.mark.parametrize("argv, message", [
    (["--walls", "q"], "unknown axis 'q'"),
    (["--walls", "x,x"], "given twice"),
    (["--cylinder", "x"], "exactly two axes"),
    (["--walls", "x", "--cylinder", "y,z"], "exclude each other"),
    (["--walls", ","], "give the axes"),
])
def test_bad_container_options_are_usage_errors(tmp_path, capfd, argv, message):
    code, _, err = _run(capfd, "generate", "random", "--n", "8", *argv, "-o", tmp_path / "s.npz")
    assert code == 2 and message in err and err.startswith("error: ")
    assert not (tmp_path / "s.npz").exists()


def test_a_cylinder_start_is_made_inside_its_circle(tmp_path, capfd):
    code, out, err = _run(capfd, "generate", "random", "--n", "40", "--d", "3", "--cylinder",
                          "x,y", "-o", tmp_path / "c.npz", "--json")
    assert code == 0, err
    packing = calippso.read(tmp_path / "c.npz")
    assert packing.boundaries == Boundaries.cylinder(3, ["x", "y"])
    reach = np.hypot(*(packing.positions[:, :2] - packing.box[:2] / 2).T)
    assert np.all(reach <= (packing.box[0] - packing.diameters) / 2 * (1 + 1e-12))
    assert json.loads(out)["boundaries"] == "cylinder cylinder periodic"


def test_generators_get_the_boundaries_only_when_they_take_them():
    container = Container("walls", ("x",))

    def periodic_only(diameters, d, *, seed):
        return seed

    def with_walls(diameters, d, *, seed, boundaries=None):
        return boundaries

    with pytest.raises(ValueError, match="--walls x: generators.periodic_only makes periodic"):
        call_with_boundaries(periodic_only, container, 3, None, 3, seed=1)
    assert call_with_boundaries(with_walls, container, 3, None, 3, seed=1) == WALLS_X
    assert call_with_boundaries(periodic_only, None, 3, None, 3, seed=1) == 1


@pytest.mark.parametrize("option", [["--walls", "x"], ["--cylinder", "x,y"]])
def test_mls_makes_a_packing_in_its_container(tmp_path, capfd, option):
    """`generate mls --walls x` (or `--cylinder x,y`) writes a jammed packing that carries
    its container."""
    code, _out, err = _run(capfd, "generate", "mls", "--n", "32", "--d", "2", *option,
                          "--final-rate", "0.1", "-o", tmp_path / "g.npz", "--quiet")
    assert code == 0, err
    packing = calippso.read(tmp_path / "g.npz")
    expected = (Boundaries.walls(2, ["x"]) if option[0] == "--walls"
                else Boundaries.cylinder(2, ["x", "y"]))
    assert packing.boundaries == expected
    expected.check(packing.positions, packing.diameters, packing.box)


def test_a_quench_between_walls_jams_on_its_own_network(tmp_path, capfd):
    """`generate quench --walls x` (a generator that takes boundaries), then `jam --network`:
    the walls survive both files and the result is isostatic with wall contacts."""
    import inspect

    import generators

    if "boundaries" not in inspect.signature(generators.soft_quench).parameters:
        pytest.skip("this soft quench makes periodic packings only")
    start, jammed = tmp_path / "q.npz", tmp_path / "qj.npz"
    code, _, err = _run(capfd, "generate", "quench", "--n", "64", "--d", "3", "--walls", "x",
                        "--seed", "1", "-o", start, "--quiet")
    assert code == 0, err
    assert calippso.read(start).boundaries == WALLS_X
    code, out, err = _run(capfd, "jam", start, "--network", start, "-o", jammed, "--json",
                          "--quiet")
    assert code == 0, err
    record = json.loads(out)
    assert record["isostatic"] and record["n_wall_contacts"] > 0
    assert read_result(jammed).packing.boundaries == WALLS_X


@pytest.mark.slow
def test_a_cylinder_round_trip(tmp_path, capfd, monkeypatch):
    """generate random --cylinder, jam, report, render: the cylinder survives, its contacts
    carry the whole load, the profile starts low at the curved wall."""
    pytest.importorskip("matplotlib")
    import functools

    monkeypatch.setattr(calippso, "report", functools.partial(calippso.report, n_bootstrap=20))
    cylinder = Boundaries.cylinder(3, ["x", "y"])
    start, jammed = tmp_path / "c.npz", tmp_path / "cj.npz"
    assert _run(capfd, "generate", "random", "--n", "64", "--cylinder", "x,y", "--seed", "1",
                "-o", start, "--quiet")[0] == 0
    code, out, err = _run(capfd, "jam", start, "-o", jammed, "--json", "--quiet")
    assert code == 0, err
    result = read_result(jammed)
    assert result.packing.boundaries == cylinder and result.isostatic
    code, _, err = _run(capfd, "report", jammed, "-o", tmp_path / "report", "--quiet")
    assert code == 0, err
    walls = json.loads((tmp_path / "report" / "summary.json").read_text())["walls"]
    (row,) = walls["loads"]
    assert row["wall"] == "cylinder" and row["contacts"] == result.n_wall_contacts > 0
    assert row["load"] == pytest.approx(np.sum(result.wall_forces), rel=1e-12)
    assert walls["layering"]["phi"][0] < 0.5 * result.phi
    code, out, err = _run(capfd, "render", jammed, "-o", tmp_path / "c.png", "--backend",
                          "matplotlib", "--size", "200", "--json")
    assert code == 0 and json.loads(out)["boundaries"] == str(cylinder)
