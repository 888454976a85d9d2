"""Slow validation of the critical exponents on ensembles of jammed LS packings.

Ensembles (monodisperse spheres, jammed with the default settings; see docs/analysis.md,
Validation). The LS inputs have a slow end: growth rate 1e-2 up to reduced pressure 1e3,
then 1e-4 up to 1e7, so that each LS end state is a jamming point (up to φ_J/φ − 1 = d/p)
and the jammed packing is the one LS reached (docs/howto/start-configurations.md):

* "d3_slow_end": d = 3, N = 1024, 34 packings;
* "d4_slow_end": d = 4, N = 512, 30 packings, with looser bands.

Bands: γ and θ_e within 0.05 of the references and θ_ℓ within 0.1 in d = 3; 0.08, 0.08 and
0.15 in d = 4. θ, the exponent of all forces, has θ_ℓ's reference and band. Each (ensemble,
exponent) band is its own test; the bands an ensemble misses are marked xfail with the
measured value (`MISSED_BANDS`). Run with

    nice -n 10 python -m pytest -m slow tests/test_analysis_validation.py

(about two hours on two cores when the packings have to be made, LS taking 180-280 s per
packing in either dimension; under a minute when they are already there).
Set CALIPPSO_VALIDATION_DIR to keep the jammed packings (one subfolder per ensemble) and the
reports written from them between runs; without it they go to a temporary folder.
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

#: The LS protocol of every ensemble: fast, then slow from SLOWDOWN_PRESSURE to PRESSURE.
PRESSURE = 1e7
GROWTH_RATE, FINAL_GROWTH_RATE, SLOWDOWN_PRESSURE = 1e-2, 1e-4, 1e3
#: θ (all forces) has θ_ℓ's reference (θ = min(θ_ℓ, θ_e)) and band.
BANDS_D3 = {"gamma": 0.05, "theta_e": 0.05, "theta_l": 0.1, "theta": 0.1}
BANDS_D4 = {"gamma": 0.08, "theta_e": 0.08, "theta_l": 0.15, "theta": 0.15}
#: name → (d, N, seeds, bands by exponent)
CASES = {"d3_slow_end": (3, 1024, range(34), BANDS_D3),
         "d4_slow_end": (4, 512, range(100, 130), BANDS_D4)}

#: (ensemble, exponent) → measured value, for the bands that are missed (docs/analysis.md).
MISSED_BANDS: dict[tuple[str, str], str] = {
    ("d3_slow_end", "theta_l"): "θ_ℓ = 0.022 [−0.043, 0.092]",
    ("d4_slow_end", "theta_e"): "θ_e = 0.314 [0.284, 0.346]",
}


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    chosen = os.environ.get("CALIPPSO_VALIDATION_DIR")
    path = Path(chosen) if chosen else tmp_path_factory.mktemp("validation")
    path.mkdir(parents=True, exist_ok=True)
    return path


def ensemble(folder: Path, d: int, n: int, seeds) -> list:
    """Jammed LS packings, loaded from `folder` when already there."""
    from generators import diameters, lubachevsky_stillinger

    folder.mkdir(parents=True, exist_ok=True)
    results = []
    for seed in seeds:
        path = folder / f"d{d}_n{n}_seed{seed}.npz"
        if not path.exists():
            start = lubachevsky_stillinger(diameters.monodisperse(n), d=d,
                                           growth_rate=GROWTH_RATE,
                                           final_growth_rate=FINAL_GROWTH_RATE,
                                           slowdown_pressure=SLOWDOWN_PRESSURE,
                                           target_pressure=PRESSURE, seed=seed).packing
            calippso.jam(start).save(path)
        results.append(calippso.load_result(path))
    return results


@pytest.fixture(scope="module")
def analyses(folder):
    """name → (results, Analysis), each computed on first use; its report goes to `folder`."""
    done = {}

    def get(name: str):
        if name not in done:
            d, n, seeds, _ = CASES[name]
            results = ensemble(folder / name, d, n, seeds)
            analysis = analyze(results, n_bootstrap=1000, seed=0)
            calippso.report(results, folder / f"report_{name}", n_bootstrap=1000, seed=0,
                            title=f"Validation ensemble {name}: d = {d}, N = {n}, LS growth "
                                  f"rate {GROWTH_RATE:g}, then {FINAL_GROWTH_RATE:g} from "
                                  f"p = {SLOWDOWN_PRESSURE:g} to {PRESSURE:g}")
            summary = {key: e.to_dict() for key, e in analysis.exponents.items()}
            (folder / f"exponents_{name}.json").write_text(json.dumps(summary, indent=1))
            done[name] = (results, analysis)
        return done[name]

    return get


@pytest.mark.parametrize("name", sorted(CASES))
def test_ensemble_is_jammed_isostatic_and_fitted(analyses, name):
    results, analysis = analyses(name)
    d = CASES[name][0]
    assert all(r.converged and r.isostatic for r in results)
    assert all(r.force_balance < 1e-9 for r in results)
    phi = analysis.contacts.phi
    low, high = (0.636, 0.65) if d == 3 else (0.45, 0.47)
    assert np.all((phi > low) & (phi < high))
    if d == 3:
        assert 0.015 <= analysis.contacts.rattler_fraction <= 0.03
    assert not analysis.exponent_errors
    assert np.all(analysis.contacts.contact_numbers >= d + 1)


def _band_case(name: str, exponent: str):
    """One (ensemble, exponent) band; the missed ones are xfail (docs/analysis.md)."""
    if (name, exponent) in MISSED_BANDS:
        return pytest.param(name, exponent, marks=pytest.mark.xfail(
            reason=f"measured outside the band: {MISSED_BANDS[(name, exponent)]} "
                   "(docs/analysis.md, Validation)", strict=False))
    return pytest.param(name, exponent)


@pytest.mark.parametrize("name, exponent", [_band_case(name, exponent) for name in sorted(CASES)
                                            for exponent in BANDS_D3])
def test_exponent_matches_reference(analyses, name, exponent):
    _, analysis = analyses(name)
    limit = CASES[name][3][exponent]
    e = analysis.exponents[exponent]
    assert abs(e.value - REFERENCE_EXPONENTS[exponent]) < limit, (
        f"{exponent} = {e.value:.4f} {e.interval} vs {REFERENCE_EXPONENTS[exponent]} ± {limit} "
        f"({name}, {analysis.contacts.n_packings} packings)")
