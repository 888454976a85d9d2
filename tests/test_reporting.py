"""calippso.report: summary JSON, figures and the Markdown page."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

import calippso
from calippso import Packing
from calippso.reporting import plot_history
from calippso.reporting._matplotlib import pyplot
from calippso.result import JammingResult
from configurations import random_sequential_addition

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def jammed_2d() -> list[JammingResult]:
    """Two small jammed disk packings (N = 128, d = 2; well under a second each)."""
    return [calippso.jam(random_sequential_addition(128, 2, 0.5, seed=s)) for s in (1, 2)]


def _images(page: str) -> list[str]:
    return re.findall(r"!\[[^\]]*\]\(([^)]+)\)", page)


def test_report_of_one_run(jammed_2d, tmp_path):
    result = jammed_2d[0]
    path = calippso.report(result, tmp_path / "one", n_bootstrap=50)
    assert path == tmp_path / "one" / "report.md" and path.is_file()
    summary = json.loads((path.parent / "summary.json").read_text())
    assert summary["d"] == 2 and summary["packings"] == 1
    assert summary["phi"]["mean"] == pytest.approx(result.phi, rel=1e-15)
    assert summary["mean_z_stable"] == pytest.approx(2 * result.n_contacts / result.n_stable)
    assert summary["rattler_fraction"] == pytest.approx(result.rattler_fraction)
    assert summary["isostatic_packings"] == int(result.isostatic)
    assert summary["runs"][0]["iterations"] == result.iterations
    assert set(summary["exponents"]) | set(summary["exponent_errors"]) == {
        "gamma", "theta_e", "theta_l", "theta"}
    page = path.read_text()
    images = _images(page)
    assert {"forces.png", "gaps.png", "contact_numbers.png", "history/run_0.png"} == set(images)
    for image in images:
        assert (path.parent / image).read_bytes()[:8] == PNG_SIGNATURE
    for name in summary["exponent_errors"]:          # too few small values in one packing
        assert "not fitted" in page
    warned = [e["warning"] for e in summary["exponents"].values() if e["warning"]]
    assert warned and summary["warnings"] == warned  # 128 disks: every fit rests on few values
    for warning in warned:
        assert f"> **Warning:** {warning}" in page
    assert page.count("(few values)") == len(warned)
    assert f"{result.phi:.6f}" in page


@pytest.mark.slow
def test_report_pools_an_ensemble(jammed_2d, tmp_path):
    path = calippso.report(jammed_2d, tmp_path, n_bootstrap=20, title="two disk packings")
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["packings"] == 2 and len(summary["runs"]) == 2
    assert summary["particles"] == 256
    assert summary["contacts"] == sum(r.n_contacts for r in jammed_2d)
    assert summary["figures"]["history"] == ["history/run_0.png", "history/run_1.png"]
    assert path.read_text().startswith("# two disk packings")
    fewer = calippso.report(jammed_2d, tmp_path / "fewer", n_bootstrap=0, max_history_figures=1)
    assert _images(fewer.read_text()).count("history/run_0.png") == 1
    assert "history/run_1.png" not in fewer.read_text()


def test_contact_numbers_show_both_the_mean_and_2d(jammed_2d, tmp_path, monkeypatch):
    """In a jammed packing mean z ≈ 2d: the 2d mark is a wide band under the thin mean line,
    and their labels sit on opposite sides."""
    from calippso.analysis import analyze
    from calippso.reporting import figures

    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda fig, path: drawn.append(fig) or save(fig, path))
    analysis = analyze(jammed_2d, n_bootstrap=0)
    figures.plot_contact_numbers(analysis, tmp_path / "contact_numbers.png")
    ax = drawn[0].axes[0]
    band, mean = sorted(ax.lines, key=lambda line: line.get_zorder())
    assert band.get_xdata()[0] == 4 and mean.get_xdata()[0] == analysis.contacts.mean_z
    assert band.get_linewidth() >= 4 * mean.get_linewidth()
    assert band.get_zorder() > max(p.get_zorder() for p in ax.patches)  # over the bars
    assert band.get_linestyle() != mean.get_linestyle()
    labels = {t.get_text(): t for t in ax.texts}
    iso, z = labels["2d = 4"], labels[f"mean z = {analysis.contacts.mean_z:.4f}"]
    assert {iso.get_ha(), z.get_ha()} == {"left", "right"}
    left = z if z.get_ha() == "right" else iso
    assert left.get_position()[0] < min(4, analysis.contacts.mean_z)
    tallest = max(p.get_height() for p in ax.patches)
    assert ax.get_ylim()[1] > tallest  # room for the labels above the bars


def test_report_refuses_bad_input(jammed_2d, tmp_path):
    with pytest.raises(ValueError, match="empty"):
        calippso.report([], tmp_path)
    cube = Packing(np.array([[1.0, 1.0, 1.0], [3.0, 3.0, 3.0]]), np.ones(2), 4.0)
    other = JammingResult(cube, np.zeros((0, 2), dtype=np.int64), np.zeros(0),
                          np.ones(2, dtype=bool), False, "hand-made", 0)
    with pytest.raises(ValueError, match="different dimensions"):
        calippso.report([jammed_2d[0], other], tmp_path)
    with pytest.raises(TypeError, match="JammingResult"):
        calippso.report(["result.npz"], tmp_path)
    with pytest.raises(ValueError, match="no history"):
        plot_history(other, tmp_path / "h.png")


def test_missing_matplotlib_is_explained(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(ImportError, match=r"calippso\[plot\]"):
        pyplot()


def test_report_is_lazy():
    code = ("import sys, calippso; f = calippso.report; a = calippso.analysis.analyze; "
            "print(callable(f), 'matplotlib' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["True", "False", "False"]
