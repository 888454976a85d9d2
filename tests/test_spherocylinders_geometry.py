"""Shaft distance (Vega–Lago) against exact cases and brute-force sampling of the segments."""

from __future__ import annotations

import math

import numpy as np
import pytest

from generators.spherocylinders import (SpherocylinderPacking, min_distance_ratio,
                                        overlapping_pairs, shaft_distance)

X, Y, Z = np.eye(3)


def brute_force(ri, ui, li, rj, uj, lj, samples=801):
    """Min over a grid of points of both segments, and the bound on its excess over the truth.

    |d(λ, μ)| is 1-Lipschitz in λ and in μ, so the grid minimum exceeds the true minimum by at
    most half a grid step on each segment.
    """
    lam = np.linspace(-li / 2, li / 2, samples)
    mu = np.linspace(-lj / 2, lj / 2, samples)
    pi_ = ri + lam[:, None] * ui
    pj = rj + mu[:, None] * uj
    # Minimise over mu for each lam in chunks to save memory.
    best = np.inf
    for chunk in np.array_split(np.arange(samples), 8):
        diff = pj[None, :, :] - pi_[chunk, None, :]
        best = min(best, float(np.sqrt((diff**2).sum(-1)).min()))
    slack = 0.5 * (li + lj) / (samples - 1)
    return best, slack


@pytest.mark.parametrize("case", [
    # name, ri, ui, li, rj, uj, lj, expected distance
    ("parallel side by side", (0, 0, 0), X, 4.0, (1, 1.5, 0), X, 2.0, 1.5),
    ("parallel, offset past the end", (0, 0, 0), X, 4.0, (5, 1.0, 0), X, 2.0,
     math.hypot(2.0, 1.0)),  # ends at x = 2 and x = 4
    ("antiparallel overlapping", (0, 0, 0), X, 4.0, (0.5, 0, 0.7), -X, 4.0, 0.7),
    ("collinear end to end", (0, 0, 0), X, 2.0, (3.5, 0, 0), X, 2.0, 1.5),
    ("collinear, one inside the other's line", (0, 0, 0), Z, 6.0, (0, 0, 1), Z, 1.0, 0.0),
    ("crossing", (0, 0, 0), X, 2.0, (0, 0, 0), Y, 2.0, 0.0),
    ("skew perpendicular", (0, 0, 0), X, 2.0, (0.3, -0.2, 0.8), Y, 2.0, 0.8),
    ("T: tip of j on the side of i", (0, 0, 0), X, 4.0, (0.5, 1.6, 0), Y, 2.0, 0.6),
    ("sphere and rod, facing the shaft", (0, 0, 0), X, 4.0, (1, 2, 0), X, 0.0, 2.0),
    ("sphere and rod, beyond the end", (0, 0, 0), X, 4.0, (5, 4, 0), Y, 0.0, 5.0),
    ("rod and sphere (order swapped)", (5, 4, 0), Z, 0.0, (0, 0, 0), X, 4.0, 5.0),
    ("two spheres", (0, 0, 0), X, 0.0, (1, 2, 2), Y, 0.0, 3.0),
    ("tilted, tips closest", (0, 0, 0), X, 2.0, (3, 0, 0), (1, 1, 0), 2.0,
     math.hypot(3 - 1 - 1 / math.sqrt(2), 1 / math.sqrt(2))),
], ids=lambda case: case[0])
def test_exact_cases(case):
    _, ri, ui, li, rj, uj, lj, expected = case
    distance, lam, mu = shaft_distance(ri, ui, li, rj, uj, lj)
    assert distance == pytest.approx(expected, abs=1e-12)
    # The returned closest points are on the segments and realise the distance.
    ui_ = np.asarray(ui, float) / np.linalg.norm(ui)
    uj_ = np.asarray(uj, float) / np.linalg.norm(uj)
    assert abs(lam) <= li / 2 + 1e-15 and abs(mu) <= lj / 2 + 1e-15
    points = np.asarray(rj) + mu * uj_ - (np.asarray(ri) + lam * ui_)
    assert np.linalg.norm(points) == pytest.approx(distance, abs=1e-12)


def test_symmetric_in_the_two_particles():
    rng = np.random.default_rng(0)
    for _ in range(200):
        ri, rj = rng.normal(size=(2, 3)) * 2
        ui, uj = rng.normal(size=(2, 3))
        li, lj = rng.uniform(0, 5, 2)
        d_ij = shaft_distance(ri, ui, li, rj, uj, lj)[0]
        d_ji = shaft_distance(rj, uj, lj, ri, ui, li)[0]
        assert d_ij == pytest.approx(d_ji, abs=1e-12)


def _random_pair(rng, kind):
    ui = rng.normal(size=3)
    ui /= np.linalg.norm(ui)
    if kind == "generic":
        uj = rng.normal(size=3)
    elif kind == "near-parallel":
        uj = ui + rng.normal(size=3) * 10 ** rng.uniform(-8, -2)
    elif kind == "near-antiparallel":
        uj = -ui + rng.normal(size=3) * 10 ** rng.uniform(-8, -2)
    else:  # exactly parallel
        uj = ui.copy()
    uj /= np.linalg.norm(uj)
    li, lj = rng.choice([0.0, 0.3, 1.0, 4.0, 10.0], 2) * rng.uniform(0.5, 1.5, 2)
    rj = rng.normal(size=3) * rng.choice([0.5, 2.0, 6.0])
    return np.zeros(3), ui, li, rj, uj, lj


@pytest.mark.parametrize("kind", ["generic", "near-parallel",
                                  pytest.param("near-antiparallel", marks=pytest.mark.slow),
                                  pytest.param("parallel", marks=pytest.mark.slow)])
def test_against_brute_force_sampling(kind):
    rng = np.random.default_rng(7)
    for _ in range(60):
        ri, ui, li, rj, uj, lj = _random_pair(rng, kind)
        distance, _, _ = shaft_distance(ri, ui, li, rj, uj, lj)
        sampled, slack = brute_force(ri, ui, li, rj, uj, lj)
        # Never above a sampled pair of points, never below the sampling bound.
        assert distance <= sampled + 1e-12
        assert distance >= sampled - slack - 1e-12


def test_local_optimality_many_pairs():
    """No small move of the returned closest points along the segments gets closer."""
    rng = np.random.default_rng(3)
    steps = np.array([-1e-4, 0.0, 1e-4])
    for trial in range(2000):
        kind = ["generic", "near-parallel", "near-antiparallel", "parallel"][trial % 4]
        ri, ui, li, rj, uj, lj = _random_pair(rng, kind)
        distance, lam, mu = shaft_distance(ri, ui, li, rj, uj, lj)
        lams = np.clip(lam + steps * max(li, 1e-300), -li / 2, li / 2)
        mus = np.clip(mu + steps * max(lj, 1e-300), -lj / 2, lj / 2)
        diff = (rj + mus[None, :, None] * uj) - (ri + lams[:, None, None] * ui)
        assert np.sqrt((diff**2).sum(-1)).min() >= distance - 1e-12


def test_periodic_minimum_image():
    box = 10.0
    distance = shaft_distance((0.5, 5, 5), Y, 2.0, (9.5, 5, 5), Z, 2.0, box=box)[0]
    assert distance == pytest.approx(1.0, abs=1e-12)


def test_invalid_input():
    with pytest.raises(ValueError, match="axis_i"):
        shaft_distance((0, 0, 0), (0, 0, 0), 1.0, (1, 0, 0), X, 1.0)
    with pytest.raises(ValueError, match="lengths"):
        shaft_distance((0, 0, 0), X, -1.0, (1, 0, 0), X, 1.0)


def test_overlap_checks_on_a_packing():
    # Two parallel rods 0.9 apart (overlap at d = 1), one far away rod.
    packing = SpherocylinderPacking(
        positions=[[5, 5, 5], [5, 5.9, 5], [5, 15, 15]], axes=[X, X, Y],
        diameters=[1.0, 1.0, 1.0], lengths=[3.0, 3.0, 3.0], box=20.0)
    assert min_distance_ratio(packing) == pytest.approx(0.9, abs=1e-12)
    np.testing.assert_array_equal(overlapping_pairs(packing), [[0, 1]])
    assert overlapping_pairs(packing, tolerance=0.2).shape == (0, 2)
    touching = SpherocylinderPacking([[5, 5, 5], [5, 6, 5]], [X, X], [1.0, 1.0], [3.0, 3.0], 20.0)
    assert min_distance_ratio(touching) == pytest.approx(1.0, abs=1e-12)
    assert overlapping_pairs(touching, tolerance=1e-9).shape == (0, 2)
