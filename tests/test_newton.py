"""The Newton stage: contact equations of an isostatic network, and its certificate."""

import numpy as np
import pytest
from configurations import random_sequential_addition

from calippso import StopReason, jam
from calippso.certification.newton import refine_isostatic
from calippso.certification.sparse_lu import pardiso_available
from calippso.geometry.packing import minimum_image


@pytest.fixture(scope="module")
def jammed():
    """A packing jammed by LPs only (no Newton stage), and its input."""
    start = random_sequential_addition(96, 3, 0.3, seed=21)
    return start, jam(start, newton=False)


def test_jammed_network_is_its_own_newton_solution(jammed):
    _, result = jammed
    packing = result.packing
    i, j = result.contacts.T
    refined = refine_isostatic(packing.positions, packing.diameters, packing.box, i, j,
                               ~result.rattlers)
    assert refined is not None and refined.positive
    assert abs(refined.sqrt_gamma_minus_1) < 1e-12
    assert refined.max_displacement < 1e-11
    # the self-stress is the LP's force network (forces of the result have mean 1)
    np.testing.assert_allclose(refined.forces / refined.forces.mean(), result.forces,
                               rtol=1e-8)


def test_newton_returns_to_the_jamming_point_from_a_perturbed_one(jammed):
    _, result = jammed
    packing = result.packing
    stable = ~result.rattlers
    pinned = np.flatnonzero(stable)[0]
    rng = np.random.default_rng(3)
    moved = packing.positions + 1e-5 * rng.standard_normal(packing.positions.shape)
    moved[pinned] = packing.positions[pinned]
    shrunk = packing.diameters * (1 - 1e-6)
    i, j = result.contacts.T
    refined = refine_isostatic(moved, shrunk, packing.box, i, j, stable)
    assert refined is not None and refined.positive
    assert refined.residual < 1e-13
    back = minimum_image(refined.positions[stable] - packing.positions[stable], packing.box)
    assert np.abs(back).max() < 1e-10
    np.testing.assert_allclose(refined.diameters, packing.diameters, rtol=1e-12)


def test_non_square_network_is_refused(jammed):
    _, result = jammed
    packing = result.packing
    i, j = result.contacts[1:].T  # one contact short: a floppy mode
    assert refine_isostatic(packing.positions, packing.diameters, packing.box, i, j,
                            ~result.rattlers) is None


def test_newton_stage_agrees_with_the_lp_only_run(jammed):
    start, lp_only = jammed
    result = jam(start)
    assert "newton" in set(result.history["stage"])
    assert result.stop_reason is StopReason.CERTIFIED_NEWTON
    assert any(note.startswith("contact equations solved by Newton") for note in result.notes)
    assert result.converged and result.isostatic
    assert result.phi == pytest.approx(lp_only.phi, rel=1e-11)
    np.testing.assert_array_equal(result.contacts, lp_only.contacts)
    np.testing.assert_allclose(result.forces, lp_only.forces, rtol=1e-8)
    assert result.force_balance < 1e-12


def test_an_lp_at_the_newton_solution_confirms_it(jammed):
    start, _ = jammed
    result = jam(start, verify_newton=True)
    assert result.converged and result.isostatic
    assert result.stop_reason is StopReason.CONVERGED
    assert "an LP at the Newton solution confirmed convergence" in result.notes
    lp_rows = result.history[result.history["stage"] == "lp"]
    assert lp_rows["sqrt_gamma_minus_1"][-1] < 1e-12
    assert lp_rows["max_displacement"][-1] < 1e-9



def test_a_round_off_force_does_not_certify():
    """A force at round-off level, relative to the largest, is a contact that could open at
    no cost: the network is not certified by it (the loose BCC lattice ended in such a
    network, with one force 1e-13 of the mean, before this rule)."""
    from dataclasses import replace

    from calippso.certification.newton import MIN_FORCE_RATIO, Refinement

    refinement = Refinement(positions=np.zeros((3, 2)), diameters=np.ones(3),
                            forces=np.array([1.0, 0.5, 2.0]), iterations=1, factorizations=1,
                            sqrt_gamma_minus_1=0.0, max_displacement=0.0, residual=0.0)
    assert refinement.positive
    assert not replace(refinement, forces=np.array([1.0, 4e-16, 2.0])).positive
    assert not replace(refinement, forces=np.array([1.0, -1e-3, 2.0])).positive
    assert replace(refinement, forces=np.array([1.0, 3 * MIN_FORCE_RATIO, 2.0])).positive


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso (the pardiso extra) is absent")
def test_pardiso_and_superlu_give_the_same_jamming_point(jammed, monkeypatch):
    """The Newton stage with PARDISO (taken from `PARDISO_MIN_UNKNOWNS` on) and with SuperLU."""
    import calippso.certification.sparse_lu as sparse_lu

    _, result = jammed
    packing = result.packing
    stable = ~result.rattlers
    shrunk = packing.diameters * (1 - 1e-6)
    i, j = result.contacts.T
    superlu = refine_isostatic(packing.positions, shrunk, packing.box, i, j, stable)
    monkeypatch.setattr(sparse_lu, "PARDISO_MIN_UNKNOWNS", 0)
    pardiso = refine_isostatic(packing.positions, shrunk, packing.box, i, j, stable)
    assert superlu is not None and pardiso is not None and pardiso.positive
    np.testing.assert_allclose(pardiso.positions, superlu.positions, rtol=0, atol=1e-13)
    np.testing.assert_allclose(pardiso.forces, superlu.forces, rtol=1e-10)


def test_chord_steps_reuse_one_factorisation(jammed):
    """From a state 1e-6 away, the first factors carry Newton to round-off and serve the
    certificate too."""
    _, result = jammed
    packing = result.packing
    stable = ~result.rattlers
    moved = packing.positions + 1e-7 * np.random.default_rng(5).standard_normal(
        packing.positions.shape)
    moved[np.flatnonzero(stable)[0]] = packing.positions[np.flatnonzero(stable)[0]]
    i, j = result.contacts.T
    refined = refine_isostatic(moved, packing.diameters * (1 - 1e-6), packing.box, i, j,
                               stable)
    assert refined is not None and refined.positive and refined.residual < 1e-13
    assert refined.factorizations == 1 and refined.iterations >= 2


def test_corrections_at_round_off_end_newton(jammed, monkeypatch):
    """Once the residual is at round-off, corrections stop shrinking (in a large network
    they stay above `STEP_TOLERANCE`): Newton ends there, at the jamming point, rather than
    failing. Here no correction can pass a zero step tolerance."""
    import calippso.certification.newton as newton

    monkeypatch.setattr(newton, "STEP_TOLERANCE", 0.0)
    _, result = jammed
    packing = result.packing
    stable = ~result.rattlers
    rng = np.random.default_rng(5)
    moved = packing.positions + 1e-6 * rng.standard_normal(packing.positions.shape)
    moved[np.flatnonzero(stable)[0]] = packing.positions[np.flatnonzero(stable)[0]]
    i, j = result.contacts.T
    refined = refine_isostatic(moved, packing.diameters * (1 - 1e-7), packing.box, i, j,
                               stable)
    assert refined is not None and refined.positive
    assert refined.residual < newton.ROUNDOFF_RESIDUAL
    assert refined.iterations < newton.MAX_ITERATIONS
    np.testing.assert_allclose(refined.diameters, packing.diameters, rtol=1e-12)
