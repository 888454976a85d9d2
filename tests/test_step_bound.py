"""The adaptive bound on displacements: while the bound limits Γ, it must not shrink."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from calippso.ilp import next_step_bound
from calippso.lp import build_lp, select_pairs
from calippso.geometry.neighbors import NeighborSearch
from calippso.settings import JamSettings
from calippso.solvers import get_solver
from calippso.step import Step, held_by_bound

from lattices import triangular


def _solved_lp(positions, diameters, box, bound, pinned=(0,)):
    search = NeighborSearch(np.asarray(positions, float), np.asarray(diameters, float),
                            np.asarray(box, float))
    fixed = np.zeros(len(diameters), dtype=bool)
    fixed[list(pinned)] = True
    lp = build_lp(select_pairs(search, bound), len(diameters), search.d, bound, fixed)
    return lp, get_solver("highs")(lp, JamSettings())


def test_pair_pressed_against_the_bound_is_held():
    # two touching discs, one pinned: the other moves away by the whole bound and Γ grows
    # with it, so the bound is what limits Γ, although the moving disc has a single contact
    lp, solution = _solved_lp([[1.0, 1.0], [2.0, 1.0]], [1.0, 1.0], [10.0, 10.0], 1e-3)
    assert solution.optimal
    assert np.abs(solution.x[2:4]).max() == pytest.approx(1e-3)
    assert held_by_bound(lp, solution)


def test_jammed_crystal_is_not_held():
    # a triangular crystal at close packing is jammed: Γ = 1 whatever the bound
    crystal = triangular(4)
    lp, solution = _solved_lp(crystal.positions, crystal.diameters, crystal.box, 1e-3)
    assert solution.optimal
    assert abs(solution.gamma) < 1e-12
    assert not held_by_bound(lp, solution)


def _step(held: bool, max_displacement: float, stable_fraction: float = 0.95) -> Step:
    return Step(lp=None, solution=None, contact_rows=np.zeros(0, dtype=np.int64),
                 rattlers=np.zeros(4, dtype=bool), forces=np.zeros(0), balance=0.0,
                 max_displacement=max_displacement, max_contacting=max_displacement,
                 stable_fraction=stable_fraction, held_by_bound=held)


def test_bound_does_not_shrink_while_it_holds_a_particle_back():
    settings = JamSettings()
    # the stable particles moved little, but a particle with d or fewer contacts was held:
    # shrinking the bound with the stable steps would stall the loop
    kept = next_step_bound(1e-4, _step(held=True, max_displacement=1e-6), settings)
    assert kept == pytest.approx(1e-4)
    grown = next_step_bound(1e-4, _step(held=True, max_displacement=1e-4), settings)
    assert grown == pytest.approx(1e-4 * settings.step_growth)
    followed = next_step_bound(1e-4, _step(held=False, max_displacement=1e-6), settings)
    assert followed == pytest.approx(1e-6 * settings.step_margin)


def test_hypostatic_warm_vertex_is_resolved_cold_unless_the_bound_holds_it():
    # the pair pressed against the bound: both discs have one contact, so the network is
    # hypostatic (no stable particle), and the bound limits Γ
    lp, solution = _solved_lp([[1.0, 1.0], [2.0, 1.0]], [1.0, 1.0], [10.0, 10.0], 1e-3)
    warm = replace(solution, warm_started=True)

    def step(solution, held):
        return Step(lp=lp, solution=solution, contact_rows=np.zeros(1, dtype=np.int64),
                     rattlers=np.ones(2, dtype=bool), forces=np.ones(1), balance=0.0,
                     max_displacement=0.0, max_contacting=1e-3, stable_fraction=0.0,
                     held_by_bound=held)

    assert step(warm, held=True).hypostatic
    assert not step(warm, held=True).needs_cold_resolve      # the bound stands in
    assert step(warm, held=False).needs_cold_resolve         # degenerate vertex: go cold
    assert not step(solution, held=False).needs_cold_resolve  # already cold
