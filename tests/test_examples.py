"""Every example runs at its tiny size and says what it should.

The examples run in this process (their ``main(argv)``; a fresh interpreter per example
costs ~2 s of imports), except those in `AS_SCRIPT`, run as ``python examples/NAME.py``.
"""

from __future__ import annotations

import runpy
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

CASES = [
    (["ls_jam_2d_bidisperse.py"], "(isostatic)"),
    (["ls_jam.py", "--d", "3"], "(isostatic)"),
    # d = 4: the script's path of d = 3 and 5, at a dimension the core tests jam already
    pytest.param(["ls_jam.py", "--d", "4"], "(isostatic)", marks=pytest.mark.slow),
    # slow: the d = 5 path is jammed by the core tests; MLS, the report and the ensemble by
    # their own tests (test_generators_mls, test_reporting, test_ensemble)
    pytest.param(["ls_jam.py", "--d", "5"], "(isostatic)", marks=pytest.mark.slow),
    pytest.param(["random_start.py"], "(isostatic)", marks=pytest.mark.slow),
    (["polydisperse_lognormal.py"], "(isostatic)"),
    pytest.param(["mls_closest_jamming.py"], "CALiPPSO moved phi", marks=pytest.mark.slow),
    (["spherocylinders.py", "--out", "{tmp}", "--picture"], "spherocylinders.png"),
    pytest.param(["force_gap_report.py", "--out", "{tmp}/report"], "report.md",
                 marks=pytest.mark.slow),
    pytest.param(["ensemble.py", "--out", "{tmp}/ensemble"], "isostatic = True",
                 marks=pytest.mark.slow),
    (["walls_layering.py", "--tiny", "--out", "{tmp}"], "(isostatic)"),
]


#: Examples run as scripts: the ensemble's worker processes import the script itself, and
#: one script checks the ``python examples/NAME.py`` entry point of them all.
AS_SCRIPT = {"ensemble.py", "ls_jam_2d_bidisperse.py"}


def test_every_example_is_tested():
    tested = {_argv(case)[0] for case in CASES}
    assert tested == {path.name for path in EXAMPLES.glob("*.py")}


def _argv(case) -> list[str]:
    return case.values[0] if hasattr(case, "values") else case[0]


@pytest.mark.parametrize("argv, expected", CASES, ids=[" ".join(_argv(c)) for c in CASES])
def test_example_runs_tiny(tmp_path, monkeypatch, capsys, argv, expected):
    if argv[0] == "force_gap_report.py" or "--picture" in argv:
        pytest.importorskip("matplotlib")
    script = EXAMPLES / argv[0]
    args = [*(a.format(tmp=tmp_path) for a in argv[1:]), "--tiny"]
    if argv[0] in AS_SCRIPT:
        run = subprocess.run([sys.executable, str(script), *args], capture_output=True,
                             text=True, timeout=300, cwd=tmp_path)
        assert run.returncode == 0, run.stderr[-2000:]
        output = run.stdout
    else:
        monkeypatch.chdir(tmp_path)
        runpy.run_path(str(script), run_name=f"example_{script.stem}")["main"](args)
        output = capsys.readouterr().out
    assert expected in output, output[-2000:]
