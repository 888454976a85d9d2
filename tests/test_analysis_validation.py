"""Slow validation of the critical exponents on ensembles of jammed LS packings.

d = 3: 12 packings of N = 1024 monodisperse spheres, LS starts at reduced pressure 1e5, jammed
with the default settings; γ and θ_e must lie within 0.05 of the references and θ_ℓ within
0.1. d = 4: 10 packings of N = 512 (a d = 4 jam of N = 1024 takes 10-15 minutes on a shared
machine), with looser bands. Run with ``nice -n 10 python -m pytest -m slow tests/test_analysis_validation.py``;
it takes tens of minutes. Set CALIPPSO_VALIDATION_DIR to keep the jammed packings (and the
report written from them) between runs; without it they go to a temporary folder.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

import calippso
from calippso.analysis import REFERENCE_EXPONENTS, analyze

pytestmark = pytest.mark.slow

PRESSURE = 1e5
#: d → (N, seeds, tolerance on γ, θ_e, θ_ℓ)
CASES = {3: (1024, range(12), {"gamma": 0.05, "theta_e": 0.05, "theta_l": 0.1}),
         4: (512, range(100, 110), {"gamma": 0.08, "theta_e": 0.08, "theta_l": 0.15})}


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


@pytest.mark.parametrize("d", sorted(CASES))
def test_exponents_of_an_ensemble(folder, d):
    n, seeds, tolerance = CASES[d]
    results = ensemble(folder, d, n, seeds)
    assert all(r.converged and r.isostatic for r in results)
    analysis = analyze(results, n_bootstrap=1000, seed=0)
    calippso.report(results, folder / f"report_d{d}", n_bootstrap=1000, seed=0,
                    title=f"Validation ensemble, d = {d}, N = {n}")
    summary = {name: e.to_dict() for name, e in analysis.exponents.items()}
    (folder / f"exponents_d{d}.json").write_text(json.dumps(summary, indent=1))
    assert not analysis.exponent_errors
    for name, limit in tolerance.items():
        exponent = analysis.exponents[name]
        assert abs(exponent.value - REFERENCE_EXPONENTS[name]) < limit, (
            f"{name} = {exponent.value:.4f} {exponent.interval} vs "
            f"{REFERENCE_EXPONENTS[name]} (d = {d}, {len(results)} packings)")
