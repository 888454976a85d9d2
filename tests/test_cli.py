"""The `calippso` command: outputs, JSON summaries, exit codes and one-line errors."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

import calippso
from calippso import Packing
from calippso.cli import cli, main
from calippso.cli.progress import LPProgress
from calippso.history import HISTORY_COLUMNS, history_from_records


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
    # a PNG name is required
    code, _, err = _run(capfd, "render", rods, "-o", tmp_path / "rods.jpg")
    assert code == 2 and "png" in err


def test_render_draws_spheres_from_any_readable_file(capfd, tmp_path, start_2d):
    import matplotlib.image

    assert _run(capfd, "jam", start_2d, "-o", tmp_path / "jammed.npz", "--quiet")[0] == 0
    result = calippso.load_result(tmp_path / "jammed.npz")
    assert _run(capfd, "convert", tmp_path / "jammed.npz", tmp_path / "jammed.xyz")[0] == 0
    rattlers = int(result.rattlers.sum())
    for source, known in ((tmp_path / "jammed.npz", rattlers),
                          (tmp_path / "jammed.xyz", rattlers), (start_2d, None)):
        picture = tmp_path / f"{source.stem}.png"
        code, out, err = _run(capfd, "render", source, "-o", picture, "--size", "160", "--json")
        assert code == 0, err
        record = json.loads(out)
        assert (record["particles"], record["n"], record["d"]) == ("disks", 32, 2)
        assert record["rattlers"] == known
        assert matplotlib.image.imread(picture).shape[:2] == (160, 160)
    spheres = tmp_path / "spheres.xyz"
    calippso.write(Packing(np.array([[0.5, 0.5, 0.5], [2.0, 2.0, 2.0]]), np.ones(2), 4.0),
                   spheres)
    code, out, _ = _run(capfd, "render", spheres, "-o", tmp_path / "s.png", "--backend",
                        "matplotlib", "--json")
    assert code == 0 and json.loads(out)["particles"] == "spheres"
    code, _, err = _run(capfd, "render", spheres, "-o", tmp_path / "s.png", "--colour-by",
                        "orientation")
    assert code == 2 and "spheres have no orientation" in err


def test_jam_json_is_the_only_stdout(capfd, tmp_path, start_2d):
    code, out, err = _run(capfd, "jam", start_2d, "-o", tmp_path / "jammed.npz", "--json")
    assert code == 0
    record = json.loads(out)  # a solver banner would break this: it goes to stderr
    assert record["converged"] and record["isostatic"] and record["d"] == 2
    assert "LP" in err  # the progress bar
    result = calippso.load_result(tmp_path / "jammed.npz")
    assert result.n_contacts == record["n_contacts"]


def _bar_count(err: str) -> int:
    """The LP count of the last state of the tqdm bar written to stderr."""
    return int(re.findall(r"LP: (\d+) LP \[", err)[-1])


def test_lp_bar_counts_the_lps_of_the_summary(capfd, tmp_path, start_2d):
    code, out, err = _run(capfd, "jam", start_2d, "-o", tmp_path / "jammed.npz", "--json")
    assert code == 0
    iterations = json.loads(out)["iterations"]
    assert _bar_count(err) == iterations
    stages = calippso.load_result(tmp_path / "jammed.npz").history["stage"].tolist()
    assert stages.count("lp") + stages.count("cleanup") == iterations
    assert "newton" in stages and "stage=Newton" in err  # shown as a label, not as an LP


def _record(stage: str) -> dict:
    return {name: stage if name == "stage" else 1 for name in HISTORY_COLUMNS}


def test_lp_bar_ticks_only_for_lp_stages(capfd):
    """The network guess and the Newton stage are labels; the clean-up LP (seen only in the
    finished history) is one more LP, as in `JammingResult.iterations`."""
    records = [_record(stage) for stage in ("guess", "lp", "lp", "newton", "cleanup")]
    bar = LPProgress(True)
    for record in records[:-1]:  # jam's callback never sees the clean-up LP
        bar(record)
    assert bar.lps == 2 and "stage=network guess" in capfd.readouterr().err
    bar.catch_up(history_from_records(records))
    bar.close()
    err = capfd.readouterr().err
    assert bar.lps == 3 and _bar_count(err) == 3 and "stage=clean-up LP" in err


def test_lp_bar_shows_a_pivot_path_as_it_goes(capfd):
    """A provisional pivot record (stage "pivot") shows the pivots taken and the forces still
    non-positive beside the bar, and ticks no LP."""
    bar = LPProgress(True)
    bar(_record("lp"))
    bar({**_record("pivot"), "pivots": 7, "non_positive": 3})
    bar.close()
    err = capfd.readouterr().err
    assert bar.lps == 1 and "pivots=7" in err and "non-positive=3" in err


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
    """Six disks (enough to jam in d = 2) of which the first two overlap."""
    path = tmp_path / "overlap.npz"
    positions = [[1.0, 1.0], [1.5, 1.0], [3.0, 3.0], [4.5, 1.0], [1.0, 4.5], [4.5, 4.5]]
    calippso.write(Packing(positions, np.ones(6), 6.0), path)
    return path


def test_errors_from_jamming_a_file_name_it(tmp_path):
    path = _overlapping(tmp_path)
    run = CliRunner().invoke(cli, ["jam", str(path), "-o", str(tmp_path / "out.npz")])
    assert run.exit_code == 1 and isinstance(run.exception, ValueError)
    assert str(run.exception).startswith(f"{path}: overlapping particles in the input")
    assert not (tmp_path / "out.npz").exists()


def test_errors_from_reading_or_writing_a_file_name_it(tmp_path):
    d4 = _four_d(tmp_path)
    xyz = tmp_path / "d4.xyz"
    for argv, named, message in ((["convert", d4, xyz], xyz, "extended XYZ holds d <= 3"),
                                 (["render", d4, "-o", tmp_path / "d4.png"], d4, "d = 4")):
        run = CliRunner().invoke(cli, list(map(str, argv)))
        assert isinstance(run.exception, ValueError), run.output
        assert str(run.exception).startswith(f"{named}: ") and message in str(run.exception)


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


@pytest.fixture
def figures_not_drawn(monkeypatch):
    """Reports whose figures are built but not laid out or written (an empty file stands for
    each PNG): the report commands' records and summaries are what these tests check; the
    figures themselves are drawn and checked in tests/test_reporting.py (~1 s each)."""
    from calippso.reporting import _matplotlib, figures

    def unsaved(fig, path):
        _matplotlib.pyplot().close(fig)
        path.touch()
        return path

    monkeypatch.setattr(figures, "_save", unsaved)


def test_report_and_demo(capfd, tmp_path, figures_not_drawn):
    if not hasattr(calippso, "report"):
        pytest.skip("calippso.report is not available")
    code, out, err = _run(capfd, "demo", "--n", "32", "-o", tmp_path / "demo", "--json")
    assert code == 0, err
    record = json.loads(out)
    assert record["converged"] and (tmp_path / "demo" / "jammed.npz").exists()
    code, out, err = _run(capfd, "report", tmp_path / "demo" / "jammed.npz", "-o",
                          tmp_path / "chosen", "--model", "power_law", "--rule", "response",
                          "--quiet")
    assert code == 0, err
    summary = json.loads((tmp_path / "chosen" / "summary.json").read_text())
    assert {e["model"] for e in summary["exponents"].values()} <= {"power_law"}
    assert summary["localization_rule"] == "response"
    code, out, err = _run(capfd, "report", tmp_path / "demo" / "jammed.npz", "-o",
                          tmp_path / "bad", "--model", "exponential")
    assert code != 0 and "exponential" in err


def test_report_of_a_folder_pools_its_results(capfd, tmp_path, start_2d, figures_not_drawn):
    folder = tmp_path / "ensemble"
    for name in ("packing_000000.npz", "packing_000001.h5"):
        assert _run(capfd, "jam", start_2d, "-o", folder / name, "--quiet")[0] == 0
    calippso.write(calippso.read(start_2d), folder / "state_000002_jam.npz")  # no result
    (folder / "summary.csv").write_text("seed,state\n")
    code, out, err = _run(capfd, "report", folder, "-o", tmp_path / "report", "--json")
    assert code == 0, err
    record = json.loads(out)
    assert record["results"] == [str(folder / "packing_000000.npz"),
                                 str(folder / "packing_000001.h5")]
    assert record["skipped"] == [str(folder / "state_000002_jam.npz")]
    assert json.loads((tmp_path / "report" / "summary.json").read_text())["packings"] == 2
    (tmp_path / "empty").mkdir()
    code, _, err = _run(capfd, "report", tmp_path / "empty", "-o", tmp_path / "none")
    assert code == 1 and err == f"error: {tmp_path / 'empty'}: a folder with no result file " \
                                "(.npz, .h5, .hdf5) in it\n"


@pytest.mark.slow
def test_report_warns_when_a_fit_rests_on_few_values(capfd, tmp_path):
    from configurations import random_sequential_addition

    from calippso.analysis.fits import MIN_RELIABLE_POINTS

    calippso.jam(random_sequential_addition(128, 2, 0.5, seed=1)).save(tmp_path / "jammed.npz")
    code, out, err = _run(capfd, "report", tmp_path / "jammed.npz", "-o", tmp_path / "report")
    assert code == 0, err
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    few = {name: e["points_in_window"] for name, e in summary["exponents"].items()
           if e["points_in_window"] < MIN_RELIABLE_POINTS}
    assert few and len(summary["warnings"]) == len(few)  # 128 disks: every fit is flagged
    for name, points in few.items():
        assert summary["exponents"][name]["warning"] in summary["warnings"]
        assert f"rests on only {points} values" in summary["exponents"][name]["warning"]
    for warning in summary["warnings"]:
        assert f"warning: {warning}\n" in out
        assert f"> **Warning:** {warning}" in (tmp_path / "report" / "report.md").read_text()
    code, out, _ = _run(capfd, "report", tmp_path / "jammed.npz", "-o", tmp_path / "again",
                        "--json")
    assert json.loads(out)["warnings"] == summary["warnings"]


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
    assert "compressed by Lubachevsky-Stillinger" in record["precompress"]["note"]
    assert record["precompress"]["reduced_pressure"] >= 1e5


def test_jam_network_first_options(capfd, tmp_path, start_2d):
    """A jammed result jammed again with its own network as the hint: no LP; 'require' on a
    loose start fails on one line; a hint file without contacts is named in the error."""
    jammed = tmp_path / "jammed.npz"
    assert _run(capfd, "jam", start_2d, "-o", jammed, "--quiet")[0] == 0
    code, out, _ = _run(capfd, "jam", jammed, "-o", tmp_path / "again.npz", "--network", jammed,
                        "--network-first", "require", "--json", "--quiet")
    assert code == 0
    record = json.loads(out)
    assert record["iterations"] == 0 and record["isostatic"]
    again = calippso.load_result(tmp_path / "again.npz")
    assert any(note.startswith("the input's own contact network (given as a hint")
               for note in again.notes)
    np.testing.assert_array_equal(again.contacts, calippso.load_result(jammed).contacts)
    code, _, err = _run(capfd, "jam", start_2d, "-o", tmp_path / "x.npz", "--network-first",
                        "require", "--quiet")
    assert code != 0 and "network_first='require'" in err and len(err.strip().splitlines()) == 1
    code, _, err = _run(capfd, "jam", start_2d, "-o", tmp_path / "y.npz", "--network",
                        start_2d, "--quiet")
    assert code != 0 and str(start_2d) in err and "no 'contacts' array" in err


def test_jam_of_one_sphere_says_why_it_cannot_jam(capfd, tmp_path):
    single = tmp_path / "one.npz"
    calippso.write(Packing(np.array([[1.0, 2.0, 3.0]]), np.array([1.0]), np.full(3, 5.0)),
                   single)
    code, _, err = _run(capfd, "jam", single, "-o", tmp_path / "out.npz", "--quiet")
    assert code != 0
    assert err.strip().count("\n") == 0 and "Traceback" not in err
    assert str(single) in err and "cannot jam 1 particle(s) in d = 3" in err


def test_generate_quench_keeps_its_network_for_jam(capfd, tmp_path):
    """The quench's .npz carries its overlap network, and `jam --network` tries it first."""
    start = tmp_path / "quench.npz"
    argv = ["generate", "quench", "--n", "256", "--d", "3", "--seed", "1", "--checkpoint",
            tmp_path / "state.npz", "--json", "--quiet"]
    code, out, _ = _run(capfd, *argv, "-o", start)
    assert code == 0 and json.loads(out)["protocol"] == "quench"
    code, again, _ = _run(capfd, *argv, "-o", tmp_path / "again.npz")  # read back from its state
    assert code == 0 and json.loads(again)["phi"] == json.loads(out)["phi"]
    with np.load(start) as stored:
        assert stored["contacts"].ndim == 2 and stored["contacts"].shape[1] == 2
    code, out, _ = _run(capfd, "jam", start, "--network", start, "-o", tmp_path / "jammed.npz",
                        "--json", "--quiet")
    assert code == 0
    record = json.loads(out)
    assert record["isostatic"] and record["force_balance"] < 1e-12
    notes = calippso.load_result(tmp_path / "jammed.npz").notes
    assert any("given as a hint" in note or "(hint: " in note for note in notes)


def test_jam_pivots_option(capfd, tmp_path, start_2d):
    """--pivots reaches jam: 'network_first' and 'off' jam this start to the same certified
    packing, and an unknown mode ('always' included) is a usage error."""
    results = {}
    for mode in ("network_first", "off"):
        path = tmp_path / f"{mode}.npz"
        assert _run(capfd, "jam", start_2d, "-o", path, "--pivots", mode, "--quiet")[0] == 0
        results[mode] = calippso.load_result(path)
        assert results[mode].converged and results[mode].isostatic
    np.testing.assert_array_equal(results["network_first"].contacts, results["off"].contacts)
    for mode in ("some", "always"):
        code, _, err = _run(capfd, "jam", start_2d, "-o", tmp_path / "z.npz", "--pivots", mode)
        assert code == 2 and "--pivots" in err


def test_generate_quench_minimiser_option(capfd, tmp_path):
    """--minimiser reaches soft_quench (the JSON record names the one that ran, auto picks by
    the dimension), offers what soft_quench offers, and an unknown value is a usage error."""
    from calippso.cli.generate import QUENCH_MINIMISERS
    from generators.soft_quench import MINIMISERS, LBFGS_FROM_DIMENSION

    assert QUENCH_MINIMISERS == MINIMISERS
    for minimiser in ("fire", "lbfgs", "auto", "newton"):
        code, out, _ = _run(capfd, "generate", "quench", "--n", "64", "--d", "3", "--seed", "1",
                            "--minimiser", minimiser, "-o", tmp_path / f"{minimiser}.npz",
                            "--json", "--quiet")
        assert code == 0
        ran = json.loads(out)["minimiser"]
        auto = "lbfgs" if 3 >= LBFGS_FROM_DIMENSION else "fire"
        assert ran == (auto if minimiser == "auto" else minimiser)
    code, _, err = _run(capfd, "generate", "quench", "--n", "64", "--minimiser", "bfgs",
                        "-o", tmp_path / "x.npz")
    assert code == 2 and "--minimiser" in err
