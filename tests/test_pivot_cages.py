"""Cages in the pivot path (`calippso.certification.pivots.cages`): a rattler whose cage
closes along the floppy mode before any pair of the ratio test joins the network there.

The starts in tests/data are network first's first pivot paths on soft quenches (d = 3,
monodisperse, quenched to p = 1e-6 by `generators.soft_quench` with its defaults; N = 1024
seed 5 and N = 2048 seed 1), read at their Newton point: positions, diameters and box in
mean diameters, the isostatic network (i, j) and the rattlers. Each meets a cage that closes
first: one rattler at N = 1024, two rattlers that share a cage at N = 2048.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calippso.certification.pivots import pivot_to_jamming
from calippso.certification.pivots.cages import closing_cages
from calippso.geometry.neighbors import NeighborSearch

from conftest import assert_jammed
from test_pivots import certified_again

DATA = Path(__file__).parent / "data"
#: The step of the cage test agrees with the exact closing step to this (relative).
SAME_STEP = 1e-6
#: Relative gap of the symmetric cage's pairs at the start.
CAGE_START_GAP = 1e-3


def symmetric_cage(speed: float) -> tuple[NeighborSearch, np.ndarray, np.ndarray]:
    """A rattler (particle 0) at the centre of three unit disks at 120°, each at relative gap
    `CAGE_START_GAP`, and a mode that moves the three towards the centre at `speed` per unit
    inflation: (search, stable, mode)."""
    centre = np.array([3.0, 3.0])
    angles = np.deg2rad([90.0, 210.0, 330.0])
    outward = np.column_stack([np.cos(angles), np.sin(angles)])
    positions = np.vstack([centre, centre + (1.0 + CAGE_START_GAP) * outward])
    stable = np.array([False, True, True, True])
    mode = np.vstack([np.zeros(2), -speed * outward])
    return NeighborSearch(positions, np.ones(4), np.full(2, 6.0)), stable, mode


def test_a_symmetric_cage_closes_where_its_pairs_touch():
    """The cage closes at the step t where (1 + h − v t)² = 1 + t (Φ = |r|²/σ² − 1 − t = 0
    on the three pairs at once), with the rattler still at the centre."""
    speed = 1.0
    search, stable, mode = symmetric_cage(speed)
    closures = closing_cages(search, stable, mode, before=np.inf)
    assert len(closures) == 1
    closure = closures[0]
    r0 = 1.0 + CAGE_START_GAP
    # (r0 − v t)² − 1 − t = 0, the smaller root
    a, b, c = speed**2, -(2.0 * r0 * speed + 1.0), r0**2 - 1.0
    exact = (-b - np.sqrt(b * b - 4.0 * a * c)) / (2.0 * a)
    assert closure.step == pytest.approx(exact, rel=SAME_STEP)
    np.testing.assert_array_equal(closure.rattlers, [0])
    assert sorted(zip(closure.i, closure.j)) == [(0, 1), (0, 2), (0, 3)]
    assert np.abs(closure.displacements).max() < SAME_STEP * CAGE_START_GAP


def test_a_cage_that_opens_or_closes_later_is_not_reported():
    """A mode that moves the cage outwards never closes it; a cage that closes after the
    ratio test's pair (`before`) does not matter."""
    search, stable, mode = symmetric_cage(1.0)
    assert closing_cages(search, stable, -mode, before=np.inf) == []
    closes = closing_cages(search, stable, mode, before=np.inf)[0].step
    assert closing_cages(search, stable, mode, before=0.5 * closes) == []


def run_from(name: str):
    start = np.load(DATA / name)
    path, failure = pivot_to_jamming(start["positions"], start["diameters"], start["box"],
                                     start["i"], start["j"], start["rattlers"])
    assert path is not None and path.jammed, failure
    return path, start["box"]


def test_a_closing_cage_joins_the_network_and_the_path_ends_jammed():
    """N = 1024: one rattler's cage closes before the ratio test's pair; the rattler joins the
    network with the d + 1 pairs that closed, Γ never falls, and `jam` certifies the end by
    itself (network first, no LP) at the same point."""
    path, box = run_from("cage_closing_start_n1024.npz")
    assert any(swap.rejoined == 1 for swap in path.swaps)
    assert all(swap.growth >= 0 for swap in path.swaps)
    assert certified_again(path, box)


def test_two_rattlers_in_one_cage_join_together():
    """N = 2048: two rattlers near each other share a cage that closes; both join, with the
    2 d + 1 pairs that closed, and the path ends certified."""
    path, box = run_from("cage_cluster_start_n2048.npz")
    assert any(swap.rejoined == 2 for swap in path.swaps)
    assert certified_again(path, box)
