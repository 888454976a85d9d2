"""The `calippso` command: outputs, JSON summaries, exit codes and one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import calippso
from calippso import Packing
from calippso.cli import main


def _run(capfd, *argv) -> tuple[int, str, str]:
    code = main(list(map(str, argv)))
    captured = capfd.readouterr()
    return code, captured.out, captured.err


@pytest.fixture(scope="module")
def start_2d(tmp_path_factory):
    """A small bidisperse LS packing in d = 2, made through the CLI."""
    path = tmp_path_factory.mktemp("cli") / "start.npz"
    assert (
        main(
            [
                "generate",
                "ls",
                "--n",
                "32",
                "--d",
                "2",
                "--distribution",
                "bidisperse",
                "--seed",
                "3",
                "-o",
                str(path),
                "--quiet",
            ]
        )
        == 0
    )
    return path


def test_generate_writes_the_packing_and_a_json_record(capfd, tmp_path):
    code, out, err = _run(
        capfd,
        "generate",
        "fb",
        "--n",
        "24",
        "--d",
        "3",
        "--seed",
        "1",
        "-o",
        tmp_path / "fb.xyz",
        "--json",
    )
    assert code == 0
    record = json.loads(out)
    assert record["protocol"] == "fb" and record["n"] == 24
    assert calippso.read(tmp_path / "fb.xyz").phi == pytest.approx(record["phi"], rel=1e-12)


def test_generate_ls_with_a_slow_end(capfd, tmp_path):
    code, out, _ = _run(capfd, "generate", "ls", "--n", "64", "--d", "3", "--pressure", "1e4",
                        "--final-growth-rate", "1e-3", "--slowdown-pressure", "1e2",
                        "-o", tmp_path / "ls.npz", "--json", "--quiet")
    assert code == 0
    assert json.loads(out)["reduced_pressure"] >= 1e4
    code, _, err = _run(capfd, "generate", "ls", "--n", "64", "--d", "3",
                        "--final-growth-rate", "0.1", "-o", tmp_path / "bad.npz", "--quiet")
    assert code != 0 and "final_growth_rate 0.1 exceeds growth_rate 0.01" in err


def test_generate_spherocylinders_records_the_start(capfd, tmp_path):
    from generators.spherocylinders import min_distance_ratio, read_xyz

    out_file = tmp_path / "rods.xyz"
    code, out, _ = _run(capfd, "generate", "spherocylinders", "--n", "60", "--aspect-ratio", "1",
                        "--contraction-rate", "1e-2", "--initial-density", "0.9", "-o", out_file,
                        "--json", "--quiet")
    assert code == 0
    record = json.loads(out)
    assert record["initial_density"] == 0.9 and record["n"] == 60
    packing = read_xyz(out_file)
    assert packing.phi == pytest.approx(record["phi"], rel=1e-9)
    assert min_distance_ratio(packing) >= 1.0 - 1e-9


def test_generate_spherocylinders_resumes_from_its_checkpoint(capfd, tmp_path):
    argv = ["generate", "spherocylinders", "--n", "150", "--aspect-ratio", "1",
            "--contraction-rate", "1e-2", "--checkpoint", tmp_path / "state.npz", "--json",
            "--quiet"]
    code, first, _ = _run(capfd, *argv, "-o", tmp_path / "a.xyz")
    assert code == 0 and (tmp_path / "state.npz").exists()
    code, again, _ = _run(capfd, *argv, "-o", tmp_path / "b.xyz")  # the finished run, read back
    assert code == 0
    assert json.loads(again)["phi"] == json.loads(first)["phi"]
    assert json.loads(again)["steps"] == json.loads(first)["steps"]


def test_render_draws_a_spherocylinder_packing(capfd, tmp_path):
    rods = tmp_path / "rods.xyz"
    assert main(["generate", "spherocylinders", "--n", "130", "--aspect-ratio", "2",
                 "--contraction-rate", "1e-2", "-o", str(rods), "--quiet"]) == 0
    capfd.readouterr()
    picture = tmp_path / "rods.png"
    code, out, _ = _run(capfd, "render", rods, "-o", picture, "--backend", "matplotlib",
                        "--size", "200", "--json")
    assert code == 0
    record = json.loads(out)
    assert record["n"] == 130 and record["output"] == str(picture)
    import matplotlib.image

    assert matplotlib.image.imread(picture).shape[:2] == (200, 200)
    # a PNG name is required, and a file without orientations is refused on one line
    code, _, err = _run(capfd, "render", rods, "-o", tmp_path / "rods.jpg")
    assert code == 2 and "png" in err
    spheres = tmp_path / "spheres.xyz"
    calippso.write(calippso.Packing(np.array([[0.5, 0.5, 0.5], [2.0, 2.0, 2.0]]),
                                    np.ones(2), np.full(3, 4.0)), spheres)
    code, _, err = _run(capfd, "render", spheres, "-o", picture)
    assert code == 1 and err.startswith("error:") and "missing" in err


def test_jam_json_is_the_only_stdout(capfd, tmp_path, start_2d):
    code, out, err = _run(capfd, "jam", start_2d, "-o", tmp_path / "jammed.npz", "--json")
    assert code == 0
    record = json.loads(out)  # a solver banner would break this: it goes to stderr
    assert record["converged"] and record["isostatic"] and record["d"] == 2
    assert "LP" in err  # the progress bar
    result = calippso.load_result(tmp_path / "jammed.npz")
    assert result.n_contacts == record["n_contacts"]


def test_quiet_jam_prints_only_the_summary(capfd, tmp_path, start_2d):
    code, out, err = _run(capfd, "jam", start_2d, "-o", tmp_path / "jammed.h5", "--quiet")
    assert code == 0 and "(isostatic)" in out and "LP" not in err
    assert calippso.io.read_result(tmp_path / "jammed.h5").converged


def test_convert_keeps_a_full_result(capfd, tmp_path, start_2d):
    assert _run(capfd, "jam", start_2d, "-o", tmp_path / "r.npz", "--quiet")[0] == 0
    code, out, _ = _run(capfd, "convert", tmp_path / "r.npz", tmp_path / "r.h5", "--json")
    assert code == 0 and json.loads(out)["kind"] == "result"
    code, out, _ = _run(capfd, "convert", tmp_path / "r.npz", tmp_path / "r.gsd", "--json")
    assert code == 0 and calippso.read(tmp_path / "r.gsd").n == 32


def _overlapping(tmp_path):
    path = tmp_path / "overlap.npz"
    calippso.write(Packing([[1.0, 1.0], [1.5, 1.0], [3.0, 3.0]], [1.0, 1.0, 1.0], 6.0), path)
    return path


def _four_d(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / "d4.npz"
    calippso.write(Packing(rng.random((10, 4)) * 5, np.full(10, 0.5), 5.0), path)
    return path


@pytest.mark.parametrize(
    "argv, code, message",
    [
        (["jam"], 2, "Missing argument"),
        (["jam", "x.npz"], 2, "Missing option"),
        (["generate", "ls", "--n", "1", "-o", "x.npz"], 2, "--n"),
        (["generate", "ls", "--pressure", "-5", "-o", "x.npz"], 2, "--pressure"),
        (["frobnicate"], 2, "No such command"),
        (["generate", "spherocylinders", "-o", "rods.npz"], 2, "extended XYZ"),
        (
            ["generate", "mls", "--input", "{tmp}/missing.npz", "-o", "{tmp}/out.npz"],
            1,
            "no such file",
        ),
        (["jam", "{tmp}/missing.npz", "-o", "{tmp}/out.npz"], 1, "no such file"),
        (["jam", "{overlap}", "-o", "{tmp}/out.npz"], 1, "overlap"),
        (["jam", "{overlap}", "-o", "{tmp}/o.npz", "--interior-point", "simplex"], 2,
         "--interior-point"),
        (["convert", "{d4}", "{tmp}/d4.xyz"], 1, "d = 4"),
        (["convert", "{d4}", "{tmp}/d4.pdb"], 1, "unknown output format"),
        (["report", "{d4}", "-o", "{tmp}/report"], 1, "missing keys"),
    ],
)
def test_errors_are_one_line_with_exit_codes(capfd, tmp_path, argv, code, message):
    names = {"tmp": tmp_path, "overlap": _overlapping(tmp_path), "d4": _four_d(tmp_path)}
    argv = [arg.format(**names) for arg in argv]
    got, out, err = _run(capfd, *argv)
    assert got == code
    assert err.startswith("error: ") and err.count("\n") == 1 and message.lower() in err.lower()
    assert not (tmp_path / "out.npz").exists()


def test_bare_command_shows_help(capfd):
    code, out, _ = _run(capfd)
    assert code == 0 and "Commands:" in out and "jam" in out


def test_not_converged_is_exit_3_and_still_written(capfd, tmp_path, start_2d):
    code, out, err = _run(
        capfd, "jam", start_2d, "-o", tmp_path / "r.npz", "--max-iters", "1", "--json"
    )
    assert code == 3 and "did not converge" in err
    assert json.loads(out)["converged"] is False and (tmp_path / "r.npz").exists()


def test_report_and_demo(capfd, tmp_path):
    if not hasattr(calippso, "report"):
        pytest.skip("calippso.report is not available")
    code, out, err = _run(capfd, "demo", "--n", "32", "-o", tmp_path / "demo", "--json")
    assert code == 0, err
    record = json.loads(out)
    assert record["converged"] and (tmp_path / "demo" / "jammed.npz").exists()
    code, out, err = _run(
        capfd, "report", tmp_path / "demo" / "jammed.npz", "-o", tmp_path / "again", "--quiet"
    )
    assert code == 0, err
    code, out, err = _run(capfd, "report", tmp_path / "demo" / "jammed.npz", "-o",
                          tmp_path / "pure", "--model", "power_law", "--quiet")
    assert code == 0, err
    summary = json.loads((tmp_path / "pure" / "summary.json").read_text())
    assert {e["model"] for e in summary["exponents"].values()} <= {"power_law"}
    code, out, err = _run(capfd, "report", tmp_path / "demo" / "jammed.npz", "-o",
                          tmp_path / "response", "--rule", "response", "--quiet")
    assert code == 0, err
    summary = json.loads((tmp_path / "response" / "summary.json").read_text())
    assert summary["localization_rule"] == "response"
    code, out, err = _run(capfd, "report", tmp_path / "demo" / "jammed.npz", "-o",
                          tmp_path / "bad", "--model", "exponential")
    assert code != 0 and "exponential" in err


def test_console_entry_points():
    for command in ([sys.executable, "-m", "calippso", "--help"],):
        run = subprocess.run(command, capture_output=True, text=True, timeout=60)
        assert run.returncode == 0 and "generate" in run.stdout
    run = subprocess.run(
        [sys.executable, "-m", "calippso", "jam", "nowhere.npz", "-o", "x.npz"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 1 and run.stderr == "error: no such file or folder: nowhere.npz\n"


def test_jam_checkpoint_resumes_to_the_same_result(capfd, tmp_path, start_2d):
    state = tmp_path / "state.npz"
    argv = ["jam", start_2d, "--checkpoint", state, "--json", "--quiet"]
    first = _run(capfd, *argv, "-o", tmp_path / "a.npz")
    assert first[0] == 0 and state.exists()
    again = _run(capfd, *argv, "-o", tmp_path / "b.npz")
    assert again[0] == 0
    a, b = (calippso.load_result(tmp_path / name) for name in ("a.npz", "b.npz"))
    assert a.phi == b.phi and (a.contacts == b.contacts).all()


def test_jam_precompress_option(capfd, tmp_path, start_2d):
    code, out, _ = _run(capfd, "jam", start_2d, "--precompress", "1e5", "-o",
                        tmp_path / "jammed.npz", "--json", "--quiet")
    assert code == 0
    record = json.loads(out)
    assert record["converged"] and record["isostatic"]
    assert "compressed by Lubachevsky-Stillinger" in calippso.load_result(
        tmp_path / "jammed.npz").status
