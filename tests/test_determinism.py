"""Determinism: the same input and seed give the same result bit-for-bit on one machine, for
`calippso.jam` and for the generators, in one process and across processes (every backend
in one process: tests/test_backends.py)."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import generators
from calippso import jam
from generators import diameters as dist

from configurations import bidisperse, random_sequential_addition
from conftest import jam_digest

REPO = Path(__file__).resolve().parents[1]


def generation_digest(result) -> str:
    h = hashlib.sha256()
    for array in (result.packing.positions, result.packing.diameters, result.packing.box):
        h.update(np.ascontiguousarray(array).tobytes())
    for name in ("time", "phi", "pressure", "rate"):
        h.update(np.ascontiguousarray(result.history[name]).tobytes())
    h.update(repr((result.steps, result.reduced_pressure, result.status)).encode())
    return h.hexdigest()


def start():
    return random_sequential_addition(64, 2, 0.45, seed=21, diameters=bidisperse(64, 1.4))


GENERATORS = {
    "ls": lambda: generators.lubachevsky_stillinger(dist.bidisperse(64, 1.4, 0.5, seed=2), d=2,
                                                    target_pressure=1e8, seed=3),
    "ls-d4": lambda: generators.lubachevsky_stillinger(dist.monodisperse(64), d=4,
                                                       target_pressure=1e6, seed=4),
    "mls": lambda: generators.closest_jamming(
        start=generators.poisson(dist.monodisperse(64), 3, phi=0.3, seed=5), max_pressure=1e8,
        final_rate=1e-2, seed=5),
    "fb": lambda: generators.force_biased(dist.monodisperse(64), d=3, seed=6),
    "poisson": lambda: type("R", (), {
        "packing": generators.poisson(dist.lognormal(64, 0.2, seed=7), 3, phi=0.2, seed=7),
        "history": np.zeros(0, dtype=[(n, float) for n in ("time", "phi", "pressure", "rate")]),
        "steps": 0, "reduced_pressure": 0.0, "status": ""})(),
}


@pytest.mark.parametrize("name", list(GENERATORS))
def test_generators_are_bit_for_bit_repeatable(name):
    assert generation_digest(GENERATORS[name]()) == generation_digest(GENERATORS[name]())


def test_different_seeds_differ():
    a = generators.lubachevsky_stillinger(dist.monodisperse(64), d=3, target_pressure=1e3, seed=1)
    b = generators.lubachevsky_stillinger(dist.monodisperse(64), d=3, target_pressure=1e3, seed=2)
    assert generation_digest(a) != generation_digest(b)


CHILD = textwrap.dedent("""
    import sys
    sys.path.insert(0, {tests!r})
    import generators
    from calippso import jam
    from generators import diameters as dist
    from conftest import jam_digest
    from test_determinism import generation_digest, start
    ls = generators.lubachevsky_stillinger(dist.monodisperse(64), d=3, target_pressure=1e6, seed=9)
    print(jam_digest(jam(start())), generation_digest(ls), jam_digest(jam(ls.packing)))
""")


@pytest.mark.slow
def test_separate_processes_agree():
    """Two fresh interpreters (new hash seeds, new solver state) give identical results."""
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    code = CHILD.format(tests=str(REPO / "tests"))
    outputs = []
    for hash_seed in ("1", "2"):
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              env={**env, "PYTHONHASHSEED": hash_seed}, timeout=600, cwd=REPO)
        assert done.returncode == 0, done.stderr[-2000:]
        outputs.append(done.stdout.strip().splitlines()[-1])
    assert outputs[0] == outputs[1]
    ls = generators.lubachevsky_stillinger(dist.monodisperse(64), d=3, target_pressure=1e6, seed=9)
    here = f"{jam_digest(jam(start()))} {generation_digest(ls)} {jam_digest(jam(ls.packing))}"
    assert outputs[0] == here
