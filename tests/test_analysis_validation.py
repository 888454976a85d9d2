"""Slow validation of the critical exponents on ensembles of jammed LS packings.

d = 3: 12 packings of N = 1024 monodisperse spheres, LS starts at reduced pressure 1e5, jammed
with the default settings; γ and θ_e must lie within 0.05 of the references and θ_ℓ within
0.1. d = 4: 10 packings of N = 512 (a d = 4 jam of N = 1024 takes 10-15 minutes on a shared
machine), with looser bands. The exponent bands are not met by these ensembles (marked xfail;
see docs/analysis.md). Run with

    nice -n 10 python -m pytest -m slow tests/test_analysis_validation.py

(tens of minutes). Set CALIPPSO_VALIDATION_DIR to keep the jammed packings (and the
report written from them) between runs; without it they go to a temporary folder.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

import calippso
from calippso.analysis import REFERENCE_EXPONENTS, analyze

pytestmark = pytest.mark.slow

PRESSURE = 1e5
#: d → (N, seeds, tolerance on γ, θ_e, θ_ℓ)
CASES = {3: (1024, range(12), {"gamma": 0.05, "theta_e": 0.05, "theta_l": 0.1}),
         4: (512, [*range(100, 105), *range(106, 111)],
             {"gamma": 0.08, "theta_e": 0.08, "theta_l": 0.15})}
# d = 4, seed 105 is left out: its jam had not finished after 25 minutes (see docs/analysis.md).


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    chosen = os.environ.get("CALIPPSO_VALIDATION_DIR")
    path = Path(chosen) if chosen else tmp_path_factory.mktemp("validation")
    path.mkdir(parents=True, exist_ok=True)
    return path


def ensemble(folder: Path, d: int, n: int, seeds) -> list:
    """Jammed LS packings, loaded from `folder` when already there."""
    from generators import diameters, lubachevsky_stillinger

    results = []
    for seed in seeds:
        path = folder / f"d{d}_n{n}_seed{seed}.npz"
        if not path.exists():
            start = lubachevsky_stillinger(diameters.monodisperse(n), d=d,
                                           target_pressure=PRESSURE, seed=seed).packing
            calippso.jam(start).save(path)
        results.append(calippso.load_result(path))
    return results


@pytest.fixture(scope="module")
def analyses(folder):
    """d → (results, Analysis), each computed on first use; its report goes to `folder`."""
    done = {}

    def get(d: int):
        if d not in done:
            n, seeds, _ = CASES[d]
            results = ensemble(folder, d, n, seeds)
            analysis = analyze(results, n_bootstrap=1000, seed=0)
            calippso.report(results, folder / f"report_d{d}", n_bootstrap=1000, seed=0,
                            title=f"Validation ensemble, d = {d}, N = {n}")
            summary = {name: e.to_dict() for name, e in analysis.exponents.items()}
            (folder / f"exponents_d{d}.json").write_text(json.dumps(summary, indent=1))
            done[d] = (results, analysis)
        return done[d]

    return get


@pytest.mark.parametrize("d", sorted(CASES))
def test_ensemble_is_jammed_isostatic_and_fitted(analyses, d):
    results, analysis = analyses(d)
    assert all(r.converged and r.isostatic for r in results)
    assert all(r.force_balance < 1e-9 for r in results)
    phi = analysis.contacts.phi
    low, high = (0.636, 0.65) if d == 3 else (0.45, 0.47)
    assert np.all((phi > low) & (phi < high))
    if d == 3:
        assert 0.015 <= analysis.contacts.rattler_fraction <= 0.03
    assert not analysis.exponent_errors
    assert np.all(analysis.contacts.contact_numbers >= d + 1)


@pytest.mark.xfail(reason="measured exponents lie outside the reference bands; figures and "
                          "discussion in docs/analysis.md (Validation)", strict=False)
@pytest.mark.parametrize("d", sorted(CASES))
def test_exponents_match_references(analyses, d):
    _, analysis = analyses(d)
    for name, limit in CASES[d][2].items():
        exponent = analysis.exponents[name]
        assert abs(exponent.value - REFERENCE_EXPONENTS[name]) < limit, (
            f"{name} = {exponent.value:.4f} {exponent.interval} vs "
            f"{REFERENCE_EXPONENTS[name]} (d = {d}, {analysis.contacts.n_packings} packings)")
