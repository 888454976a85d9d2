"""calippso report on packings of several sizes: grouped by N, exponents per size and
extrapolated, the figures across sizes; one size gives the report of one ensemble."""

from __future__ import annotations

import json
import re

import pytest
from click.testing import CliRunner

import calippso
from calippso.cli import cli
from configurations import random_sequential_addition

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SIZE_FIGURES = {"exponents_vs_n.png", "gaps_collapse.png"}


@pytest.fixture(scope="module")
def mixed_sizes() -> list:
    """Jammed disk packings of N = 96 and 128 (two each), in mixed order."""
    return [calippso.jam(random_sequential_addition(n, 2, 0.5, seed=seed))
            for n, seed in ((128, 1), (96, 2), (128, 3), (96, 4))]


def _images(page: str) -> set[str]:
    return set(re.findall(r"!\[[^\]]*\]\(([^)]+)\)", page))


def test_report_groups_packings_by_size(mixed_sizes, tmp_path):
    page = calippso.report(mixed_sizes, tmp_path, n_bootstrap=30, max_history_figures=0)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["packings"] == 4                        # the pooled report as before
    assert list(summary["by_size"]) == ["96", "128"]
    for n, row in summary["by_size"].items():
        assert row["packings"] == 2
        for name in ("gamma", "theta_e", "theta_l", "theta"):
            entry = row[name]
            if entry is not None:
                low, high = entry["interval"]
                assert low <= entry["value"] <= high
    for name, entry in summary["extrapolated"].items():
        assert set(entry) >= {"value", "interval", "form", "reason", "candidates"}
        assert entry["form"] == "inverse_n"                # two sizes: 1/N assumed
    assert summary["gap_cutoff"]["sizes"] == [96, 128]
    text = page.read_text()
    assert "## Sizes" in text and "| N → ∞ |" in text
    assert SIZE_FIGURES <= _images(text)
    for figure in SIZE_FIGURES:
        assert (tmp_path / figure).read_bytes()[:8] == PNG_SIGNATURE


def test_one_size_gives_the_report_of_one_ensemble(mixed_sizes, tmp_path):
    same = [r for r in mixed_sizes if r.packing.n == 128]
    page = calippso.report(same, tmp_path, n_bootstrap=0, max_history_figures=0)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert not {"by_size", "extrapolated", "gap_cutoff"} & set(summary)
    assert "## Sizes" not in page.read_text()
    assert not any((tmp_path / figure).exists() for figure in SIZE_FIGURES)


def test_cli_report_of_files_of_several_sizes(mixed_sizes, tmp_path):
    files = []
    for k, result in enumerate(mixed_sizes):
        files.append(str(result.save(tmp_path / f"run_{k}.npz")))
    out = tmp_path / "report"
    run = CliRunner().invoke(cli, ["report", *files, "-o", str(out), "--correction",
                                   "constant", "--gap-floor", "cutoff"])
    assert run.exit_code == 0, run.output
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary["by_size"]) == ["96", "128"]
    assert {e["form"] for e in summary["extrapolated"].values()} == {"constant"}
    assert summary["gap_floor"] == "cutoff"
