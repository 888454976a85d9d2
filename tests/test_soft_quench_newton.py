"""The damped Newton minimiser of the soft quench (`minimiser="newton"`, `generators._newton`).

Its gradient and Hessian against finite differences of the enthalpy (periodic, walls,
cylinder) and against the force kernel; quenches in d = 2, 3, 4 (mono and poly) that converge,
land in the density band of FIRE's quench of the same seed and hand `calippso.jam` a network
it certifies with no LP; a checkpoint resumed in the middle of a Newton phase ends bit for bit
where the uninterrupted run ends. With N = 128 every minimisation would end within the
first-order phase, so the quenches here hand over to Newton after `AFTER_STEPS` steps.
"""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from conftest import assert_jammed

import generators
from calippso import jam
from calippso.geometry.boundaries import Boundaries
from generators import _fire, _newton
from generators import diameters as dist
from generators.initial import poisson

quench_module = importlib.import_module("generators.soft_quench")

#: Steps of the first-order phase before Newton takes over, in the quenches of this file.
AFTER_STEPS = 1000
#: Finite-difference step of the derivative checks (mean diameters, and in λ).
STEP = 1e-6
#: (diameters, d, seed, φ band: as in tests/test_generators_soft_quench.py).
CASES = {
    "d2_bidisperse": (dist.bidisperse(128, 1.4, 0.5, seed=3), 2, 3, (0.825, 0.85)),
    "d3_mono": (dist.monodisperse(128), 3, 1, (0.63, 0.65)),
    "d3_lognormal": (dist.lognormal(128, 0.2, seed=2), 3, 2, (0.63, 0.67)),
    "d4_mono": (dist.monodisperse(128), 4, 1, (0.44, 0.47)),
}
#: Largest difference of φ between the Newton and the FIRE quench of the same seed: the
#: spread of φ over seeds at N = 128 (0.829–0.845 in d = 2).
PHI_SPREAD = 0.015


#: The cases of the fast suite; the others run with the slow tests.
FAST_CASES = ("d2_bidisperse", "d3_mono")


def _cases(names) -> list:
    return [name if name in FAST_CASES else pytest.param(name, marks=pytest.mark.slow)
            for name in names]


@pytest.fixture(scope="module")
def quenches():
    """``quenches(name)``: the case quenched with minimiser="newton" (Newton after
    `AFTER_STEPS` steps) and with FIRE, as (newton result, FIRE result); each made once."""
    made: dict = {}

    def quench(name: str) -> tuple:
        if name not in made:
            sizes, d, seed, _ = CASES[name]
            with pytest.MonkeyPatch.context() as patch:
                patch.setattr(quench_module, "NEWTON_AFTER_STEPS", AFTER_STEPS)
                made[name] = (generators.soft_quench(sizes, d, seed=seed, minimiser="newton"),
                              generators.soft_quench(sizes, d, seed=seed, minimiser="fire"))
        return made[name]

    return quench


@pytest.mark.parametrize("name", _cases(CASES))
def test_newton_quench_converges_in_the_band_of_fire(quenches, name):
    newton, fire = quenches(name)
    low, high = CASES[name][3]
    assert "converged" in newton.status
    assert newton.extra["minimiser"] == "newton" and newton.extra["newton_solves"] > 0
    assert 0 < newton.extra["pressure"] <= newton.extra["target_pressure"]
    assert low < newton.packing.phi < high
    assert abs(newton.packing.phi - fire.packing.phi) < PHI_SPREAD
    assert newton.extra["isostaticity_gap"] >= 0


@pytest.mark.parametrize("name", _cases(["d2_bidisperse", "d3_mono", "d3_lognormal"]))
def test_jam_certifies_the_newton_network_with_no_lp(quenches, name):
    newton, _ = quenches(name)
    result = jam(newton.packing, network=newton.contacts)
    assert "lp" not in set(result.history["stage"]) and result.iterations == 0
    assert_jammed(result)


class _Crash(Exception):
    """Stands for the process being killed."""


def test_checkpoint_resumed_in_a_newton_phase_ends_bit_for_bit(tmp_path, monkeypatch):
    """Killed at the third call of the Newton kernel (checkpoints at every pause), the
    quench resumes from its checkpoint and ends where the uninterrupted run ends."""
    monkeypatch.setattr(quench_module, "NEWTON_AFTER_STEPS", AFTER_STEPS)
    monkeypatch.setattr(quench_module, "NEWTON_PAUSE_STEPS", 2)
    sizes, d = dist.lognormal(64, 0.2, seed=5), 3
    reference = generators.soft_quench(sizes, d, seed=4, minimiser="newton")
    real_run, calls = _newton.newton_run, []

    def crashing_run(*args):
        calls.append(1)
        if len(calls) == 3:
            raise _Crash
        return real_run(*args)

    monkeypatch.setattr(_newton, "newton_run", crashing_run)
    path = tmp_path / "quench.npz"
    with pytest.raises(_Crash):
        generators.soft_quench(sizes, d, seed=4, minimiser="newton", checkpoint=path,
                               checkpoint_every=0)
    with np.load(path) as saved:
        assert saved["state_method"][quench_module.PHASE] == quench_module.NEWTON_PHASE
    monkeypatch.setattr(_newton, "newton_run", real_run)
    resumed = generators.soft_quench(sizes, d, seed=4, minimiser="newton", checkpoint=path,
                                     checkpoint_every=0)
    assert resumed.extra["resumed"]
    np.testing.assert_array_equal(resumed.packing.positions, reference.packing.positions)
    np.testing.assert_array_equal(resumed.contacts, reference.contacts)
    assert resumed.steps == reference.steps
    assert resumed.extra["newton_solves"] == reference.extra["newton_solves"]


def _system(d: int, boundaries: Boundaries | None):
    """A dense random start of 128 log-normal spheres (many overlaps), its lists built."""
    sizes = dist.lognormal(128, 0.1, seed=3)
    start = poisson(sizes, d, phi=0.9 if d == 2 else 0.75, seed=2, boundaries=boundaries)
    periodic = None if boundaries is None else boundaries.periodic
    cylinder = () if boundaries is None else boundaries.cylinder_axes
    mean = sizes.mean()
    system = quench_module._SoftSpheres(start.positions / mean, sizes / mean,
                                        start.box / mean, 0.3, "fire", periodic, cylinder)
    system.rebuild()
    return system


def _enthalpy(system, x: np.ndarray, log_scale: float, pressure: float) -> float:
    """H = E + p* V e^{−d λ}."""
    terms = _newton.evaluate(x, system.s, np.exp(log_scale), system.box, *system.lists[:2],
                             system.periodic, system.circle)
    volume = _fire.container_volume(system.box, system.circle)
    return terms.energy + pressure * volume * np.exp(-x.shape[1] * log_scale)


CONTAINERS = {"periodic": (3, None), "walls": (3, Boundaries.walls(3, ("x", "y"))),
              "cylinder": (3, Boundaries.cylinder(3, ("x", "y"))), "d2": (2, None)}


@pytest.mark.parametrize("container", CONTAINERS)
def test_gradient_and_hessian_match_finite_differences(container):
    d, boundaries = CONTAINERS[container]
    system = _system(d, boundaries)
    n = system.x.shape[0]
    x, log_scale, pressure = system.x.copy(), 0.01, 0.3
    terms = _newton.evaluate(x, system.s, np.exp(log_scale), system.box, *system.lists[:2],
                             system.periodic, system.circle)
    grad_x, virial = _newton.gradient(terms, n)
    matrix, mixed, second = _newton.hessian(terms, n)
    dense = matrix.toarray()
    # the forces, virial and energy of the FIRE kernel
    forces, pair_force = np.zeros_like(x), np.empty((system.lists[1].size, d))
    sums = _fire.harmonic_forces(x, np.zeros_like(x), system.s, np.exp(log_scale),
                                 system.box, *system.lists, pair_force, forces,
                                 _fire.work_array(n), system.periodic, system.circle)
    np.testing.assert_allclose(-grad_x, forces, atol=1e-13)
    assert virial == pytest.approx(sums[5], rel=1e-12)
    assert terms.energy == pytest.approx(sums[7], rel=1e-12)
    assert terms.h.size == sums[6] > 0
    # first and second derivatives of H against central differences
    volume = _fire.container_volume(system.box, system.circle)
    reduced = volume * np.exp(-d * log_scale)
    slope = (_enthalpy(system, x, log_scale + STEP, pressure)
             - _enthalpy(system, x, log_scale - STEP, pressure)) / (2 * STEP)
    assert slope == pytest.approx(virial - d * reduced * pressure, rel=1e-6)
    for k in range(0, n * d, 29):
        i, mu = divmod(k, d)
        ahead, behind = x.copy(), x.copy()
        ahead[i, mu] += STEP
        behind[i, mu] -= STEP
        difference = (_enthalpy(system, ahead, log_scale, pressure)
                      - _enthalpy(system, behind, log_scale, pressure)) / (2 * STEP)
        assert difference == pytest.approx(grad_x[i, mu], abs=1e-7)
        change = [_newton.gradient(_newton.evaluate(
            y, system.s, np.exp(log_scale), system.box, *system.lists[:2], system.periodic,
            system.circle), n) for y in (ahead, behind)]
        column = (change[0][0] - change[1][0]).ravel() / (2 * STEP)
        np.testing.assert_allclose(column, dense[:, k], atol=1e-6)
        assert (change[0][1] - change[1][1]) / (2 * STEP) == pytest.approx(mixed[k], abs=1e-6)
    change = [_newton.gradient(_newton.evaluate(
        x, system.s, np.exp(log_scale + sign * STEP), system.box, *system.lists[:2],
        system.periodic, system.circle), n) for sign in (1, -1)]
    np.testing.assert_allclose((change[0][0] - change[1][0]).ravel() / (2 * STEP), mixed,
                               atol=1e-6)
    assert (change[0][1] - change[1][1]) / (2 * STEP) == pytest.approx(second, rel=1e-6)
    # the Gauss–Newton part the minimiser factorises is positive semi-definite
    gauss_newton = _newton.hessian(terms, n, exact=False)[0].toarray()
    assert np.linalg.eigvalsh(gauss_newton).min() > -1e-12
