"""Slow validation of the closest-jamming protocol (d = 3, N = 1000, three seeds per start).

Run with ``pytest -m slow tests/test_generators_validation.py``, or as a script
(``python tests/test_generators_validation.py [out.jsonl]``) to print one JSON line per run,
as quoted in docs/generators.md.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

import generators
from calippso.geometry.neighbors import min_gap
from generators import diameters as dist

N = 1000
SEEDS = (1, 2, 3)


def make_start(kind: str, seed: int, diameters: np.ndarray):
    """Start configurations: Poisson points (φ = 0.3), FB (τ = 1e-3), LS to p = 1e5."""
    if kind == "poisson":
        return generators.poisson(diameters, 3, phi=0.3, seed=seed)
    if kind == "fb":
        return generators.force_biased(diameters, 3, contraction_rate=1e-3, seed=seed).packing
    return generators.lubachevsky_stillinger(diameters, d=3, target_pressure=1e5,
                                             seed=seed).packing


def jam_of_start(kind: str, start) -> dict:
    """`calippso.jam` of the start itself, beside the MLS result of the same start.

    LS starts are jammed as they are. FB starts (φ ≈ 0.61) are loose: the LP loop alone
    crawls, so they are compressed first (`calippso.protocols.precompress` to p = 1e5).
    Poisson starts overlap:
    their diameters are first scaled down by one factor until the closest pair has a gap of
    1e-9 σ (what LS and MLS do with overlapping input), then compressed the same way.
    """
    import calippso
    from calippso import protocols

    pressure = None if kind == "ls" else 1e5
    gap, _ = min_gap(start.positions, start.diameters, start.box)
    if gap < 0:
        start = calippso.Packing(start.positions, start.diameters * (1 + gap) * (1 - 1e-9),
                                 start.box)
    if pressure is not None:
        start = protocols.precompress(start, pressure).packing
    jammed = calippso.jam(start)
    return {"phi_jam_of_start": float(jammed.phi), "isostatic_start": bool(jammed.isostatic),
            "lps_of_start": jammed.iterations, "wall_time_jam_of_start": jammed.wall_time,
            "jam_of_start_precompress": pressure}


def run(kind: str, seed: int, std: float = 0.0) -> dict:
    diameters = dist.lognormal(N, std, seed=seed) if std else dist.monodisperse(N)
    start = make_start(kind, seed, diameters)
    result = generators.closest_jamming(start=start, seed=seed)
    packing = result.packing
    gap, overlapping = min_gap(packing.positions, packing.diameters, packing.box)
    record = {"start": kind, "std": std, "seed": seed, "phi_start": start.phi,
              "phi_mls": packing.phi, "pressure": result.reduced_pressure,
              "collisions_per_particle": result.steps / N, "wall_time": result.wall_time,
              "status": result.status, "overlapping_pairs": overlapping}
    try:
        import calippso

        jammed = calippso.jam(packing)
        record.update(phi_jam=float(jammed.phi), isostatic=bool(jammed.isostatic))
        record.update(jam_of_start(kind, start))
    except Exception as error:  # the jamming core is optional here
        record["jam_error"] = f"{type(error).__name__}: {error}"
    return record


@pytest.mark.slow
@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("kind", ["poisson", "fb", "ls"])
def test_closest_jamming_density_monodisperse(kind, seed):
    record = run(kind, seed)
    assert record["overlapping_pairs"] == 0
    assert record["status"].startswith(("jammed", "levelled off"))
    if record["status"].startswith("levelled off"):
        assert record["isostatic"]   # the LP certifies the packing the protocol left
    assert 0.628 < record["phi_mls"] < 0.647


@pytest.mark.slow
def test_closest_jamming_density_lognormal_02():
    record = run("poisson", 1, std=0.2)
    assert record["overlapping_pairs"] == 0
    assert 0.643 < record["phi_mls"] < 0.659


if __name__ == "__main__":
    out = open(sys.argv[1], "a") if len(sys.argv) > 1 else sys.stdout
    jobs = [(kind, seed, 0.0) for kind in ("poisson", "ls", "fb") for seed in SEEDS]
    jobs.insert(3, ("poisson", 1, 0.2))
    for kind, seed, std in jobs:
        print(json.dumps(run(kind, seed, std)), file=out, flush=True)
