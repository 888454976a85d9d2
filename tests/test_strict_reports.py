"""The box, the jamming category and the contact stress in the reports: `summary()`, the
report page and its ``summary.json``, ``calippso jam --json``."""

from __future__ import annotations

import json

import numpy as np
import pytest

import calippso
import lattices
from calippso import Boundaries, Packing
from calippso.analysis import run_record
from configurations import random_sequential_addition

#: The stress of a strictly jammed crystal is isotropic to round-off.
ISOTROPY_TOLERANCE = 1e-9


@pytest.fixture(scope="module")
def fixed() -> calippso.JammingResult:
    """A small jammed disc packing in a fixed box (N = 64, well under a second)."""
    return calippso.jam(random_sequential_addition(64, 2, 0.5, seed=3))


@pytest.fixture(scope="module")
def strict() -> calippso.JammingResult:
    """The triangular lattice jammed with a deformable box: one LP, strictly jammed."""
    return calippso.jam(lattices.triangular(4), box="deformable")


def _virial(result) -> np.ndarray:
    """Σ f r rᵀ / |r| / V over the contacts, by hand."""
    i, j = result.contacts.T
    packing = result.packing
    vectors = packing.minimum_image(packing.positions[i] - packing.positions[j])
    distances = np.linalg.norm(vectors, axis=1)
    return np.einsum("k,ka,kb->ab", result.forces / distances, vectors,
                     vectors) / packing.volume


def test_a_fixed_box_result_has_its_contact_stress(fixed):
    assert fixed.converged and fixed.stress is None and fixed.category is None
    stress = fixed.contact_stress
    assert np.allclose(stress, _virial(fixed), rtol=1e-14, atol=0.0)
    assert np.array_equal(stress, stress.T)
    assert fixed.pressure == pytest.approx(np.trace(_virial(fixed)) / 2, rel=1e-14)
    # a fixed box does not make the stress isotropic
    assert 1e-6 < fixed.stress_anisotropy < 0.5
    line = [text for text in fixed.summary().splitlines() if "box = " in text][0]
    assert line.startswith("  box = fixed; category = not tested; pressure = "
                           f"{fixed.pressure:.6g}, stress anisotropy = "
                           f"{fixed.stress_anisotropy:.1e}; stress = [[")
    record = run_record(fixed)
    assert record["box"] == "fixed" and record["category"] is None
    assert record["pressure"] == fixed.pressure
    assert record["stress_anisotropy"] == fixed.stress_anisotropy


def test_a_container_has_no_contact_stress(fixed):
    walled = calippso.JammingResult(
        packing=Packing(fixed.packing.positions + [0.5, 0.0], fixed.packing.diameters,
                        fixed.packing.box + [1.0, 0.0], Boundaries.walls(2, "x")),
        contacts=fixed.contacts, forces=fixed.forces, rattlers=fixed.rattlers,
        converged=False, status="", iterations=0)
    assert walled.contact_stress is None and np.isnan(walled.pressure)
    assert "  box = fixed; category = not tested" in walled.summary().splitlines()
    record = run_record(walled)
    assert record["pressure"] is None and record["stress_anisotropy"] is None


def test_a_deformable_result_reports_strict_with_an_isotropic_stress(strict):
    assert strict.category == "strict" and strict.contact_stress is strict.stress
    assert strict.stress_anisotropy <= ISOTROPY_TOLERANCE
    assert np.allclose(strict.stress, _virial(strict), rtol=0.0, atol=1e-12 * strict.pressure)
    assert (f"box = deformable; category = strict; pressure = {strict.pressure:.6g}"
            in strict.summary())
    record = run_record(strict)
    assert record["box"] == "deformable" and record["category"] == "strict"
    assert record["stress_anisotropy"] <= ISOTROPY_TOLERANCE
    # 32 discs, 3 contacts each: hyperstatic by the strict count, 2 (N - 1) + 3
    assert record["isostaticity_gap"] == 96 - (2 * 31 + 3)


def test_the_report_page_shows_box_category_and_stress(fixed, strict, tmp_path):
    tested = calippso.JammingResult(**{**vars(fixed), "category": "collective"})
    page = calippso.report([fixed, tested, strict], tmp_path, n_bootstrap=0,
                           max_history_figures=0).read_text()
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["categories"] == {"not tested": 1, "collective": 1, "strict": 1}
    runs = summary["runs"]
    assert [run["box"] for run in runs] == ["fixed", "fixed", "deformable"]
    assert [run["category"] for run in runs] == [None, "collective", "strict"]
    assert np.allclose(runs[0]["stress"], fixed.contact_stress, rtol=1e-15, atol=0.0)
    assert np.allclose(runs[2]["stress"], strict.stress, rtol=1e-15, atol=0.0)
    assert runs[2]["pressure"] == pytest.approx(strict.pressure, rel=1e-15)
    assert "## Box, stress and jamming category" in page
    assert "not tested: 1, collective: 1, strict: 1" in page
    rows = [line for line in page.splitlines() if line.startswith("| 2 | deformable |")]
    assert rows and rows[0].startswith(f"| 2 | deformable | strict | {strict.pressure:.6g} | ")
    assert f"| 0 | fixed | not tested | {fixed.pressure:.6g} | " \
           f"{fixed.stress_anisotropy:.1e} | [" in page


def test_cli_jam_json_has_the_stress_and_the_tested_category(fixed, tmp_path):
    from click.testing import CliRunner

    from calippso.cli import cli

    source = calippso.write(random_sequential_addition(64, 2, 0.5, seed=3), tmp_path / "in.npz")
    records = {}
    for flags in ([], ["--category"]):
        run = CliRunner().invoke(cli, ["jam", str(source), "-o", str(tmp_path / "out.npz"),
                                       "--json", *flags])
        assert run.exit_code == 0, run.output
        records[tuple(flags)] = json.loads(run.stdout)
    plain, tested = records[()], records[("--category",)]
    assert plain["box"] == "fixed" and plain["category"] is None and "box_matrix" not in plain
    saved = calippso.load_result(tmp_path / "out.npz")
    assert tested["category"] == "collective" == saved.category
    assert "category = collective" in saved.summary()
    assert np.allclose(tested["stress"], saved.contact_stress, rtol=1e-15, atol=0.0)
    assert tested["pressure"] == pytest.approx(saved.pressure, rel=1e-15)
    assert tested["stress_anisotropy"] == pytest.approx(saved.stress_anisotropy, rel=1e-12)
