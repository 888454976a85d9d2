"""LPs solved by interior point without crossover (``jam(..., crossover="off")``): the
network read by strict complementarity (`calippso.complementarity`), rattlers removed, and
the Newton stage, the contact pivots and the certificate after every LP."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import generators
from calippso import StopReason, jam
from calippso.complementarity import read_complementarity
from calippso.lp import build_lp, select_pairs
from calippso.geometry.neighbors import NeighborSearch, Pairs
from calippso import settings as settings_module
from calippso.settings import INTERIOR_LP_MIN_COLUMNS, JamSettings
from calippso.solvers import LPSolution
from calippso.solvers.highs import HighsOptions, solve
from calippso.stages import network_first_stage
from calippso.step import analyse

from configurations import bidisperse, ls_packing
from conftest import assert_jammed
from test_cylinder import assert_jammed_in_a_cylinder, cylinder_start
from test_network_first import jammed_from_ls
from test_walls import assert_jammed_between_walls, walled_start

#: φ_J of the two engines where the LP path converges in a few LPs.
SAME_PHI = 1e-9


def interior(packing, **options):
    """`jam` with the LPs solved without crossover and the LP loop from the start."""
    return jam(packing, crossover="off", network_first="off", **options)


def test_crossover_is_a_checked_setting():
    assert JamSettings().crossover == "auto"
    with pytest.raises(ValueError,
                       match=r"^unknown crossover 'maybe': choose one of auto, on, off"):
        JamSettings(crossover="maybe")
    assert HighsOptions.from_settings(JamSettings(crossover="off")).crossover is False
    assert HighsOptions.from_settings(JamSettings()).crossover is True


def test_auto_crossover_goes_off_for_large_lps():
    """"auto" is "off" from `INTERIOR_LP_MIN_COLUMNS` columns (d N + 1) on; a choice made
    by the caller stays as it is."""
    below = (INTERIOR_LP_MIN_COLUMNS - 2) // 3
    assert JamSettings().resolved(below, 3).crossover == "on"
    assert JamSettings().resolved(below + 1, 3).crossover == "off"
    assert JamSettings(crossover="on").resolved(10 * below, 3).crossover == "on"
    assert JamSettings(crossover="off").resolved(8, 2).crossover == "off"


def test_jam_takes_the_interior_engine_where_auto_says_so(ls_jammed, monkeypatch):
    """With the threshold lowered below N = 64, d = 3 (193 columns), the default run solves
    its LPs without crossover, and ends certified."""
    monkeypatch.setattr(settings_module, "INTERIOR_LP_MIN_COLUMNS", 100)
    solutions = []
    result = jam(ls_jammed.packing, network_first="off",
                 on_lp=lambda attempt: solutions.append(attempt.solution))
    assert_jammed(result)
    assert solutions and not any(solution.vertex for solution in solutions)


@pytest.mark.parametrize("d, n, seed", [
    (3, 64, 1),   # N = 128 in d = 3: the rattler test below
    pytest.param(5, 128, 1, marks=pytest.mark.slow)])   # making the d = 5 input takes ~10 s
def test_ls_inputs_end_certified(d, n, seed):
    result = interior(ls_packing(n, d, seed=seed, pressure=1e7))
    assert_jammed(result)
    assert result.stop_reason in (StopReason.CERTIFIED_NEWTON, StopReason.CERTIFIED_PIVOTS)
    lps = result.history[result.history["stage"] == "lp"]
    assert np.all(lps["ipm_iterations"] > 0)   # every LP by interior point, recorded


def test_d2_bidisperse_matches_the_vertex_engine():
    start = generators.lubachevsky_stillinger(bidisperse(128), d=2, target_pressure=1e7,
                                              seed=2).packing
    result = interior(start)
    assert_jammed(result)
    vertex = jam(start, network_first="off")
    assert result.phi == pytest.approx(vertex.phi, rel=SAME_PHI)


def test_nearly_jammed_input_reaches_the_same_phi(nearly_jammed):
    result = interior(nearly_jammed)
    assert_jammed(result)
    vertex = jam(nearly_jammed, network_first="off")
    assert result.phi == pytest.approx(vertex.phi, rel=SAME_PHI)
    assert result.n_contacts == vertex.n_contacts
    assert np.array_equal(result.rattlers, vertex.rattlers)


def test_a_rattler_is_left_mid_range_and_out_of_the_network():
    """The optimal face is degenerate (a rattler moves freely inside its cage): the
    interior solution leaves the rattler strictly inside the bound, and complementarity
    reads the same contacts as the vertex."""
    start = ls_packing(128, 3, seed=2, pressure=1e7)
    scale = start.mean_diameter
    search = NeighborSearch(start.positions / scale, start.diameters / scale, start.box / scale)
    bound = 1e-3
    fixed = np.zeros((start.n, 3), dtype=bool)
    fixed[-1] = True
    lp = build_lp(select_pairs(search, bound), start.n, 3, bound, fixed)
    vertex = solve(lp, HighsOptions())
    centre = solve(lp, HighsOptions(crossover=False))
    assert vertex.vertex and not centre.vertex and centre.ipm_iterations > 0
    reading = read_complementarity(lp, centre)
    assert np.array_equal(reading.contacts, vertex.duals > 1e-10 * vertex.duals.max())
    assert reading.margin > 1.0   # every row read apart by more than a decade
    touching = np.zeros(start.n, dtype=bool)
    touching[lp.pairs.i[reading.contacts]] = touching[lp.pairs.j[reading.contacts]] = True
    free = np.flatnonzero(~touching)
    assert free.size   # particles that no row holds: free inside their cages
    s = np.abs(centre.x[:-1].reshape(start.n, 3))
    assert s[free].max() < (1 - 1e-3) * bound
    assert np.abs(vertex.x[:-1].reshape(start.n, 3)[free]).max() == pytest.approx(bound)
    taken = analyse(lp, centre, JamSettings(crossover="off"))
    assert taken.rattlers[free].all()
    assert_jammed(interior(start))


def _one_row_lp(duals, slacks, bound=1e-2):
    """An LP of one particle pair per row whose solution has the given duals and slacks
    (the matrix is the identity on γ; only the rows and the bound matter here)."""
    m = len(duals)
    pairs = Pairs(np.zeros(m, np.int64), np.ones(m, np.int64), np.ones((m, 1)),
                  np.full(m, 2.0), np.full(m, 2.0))   # σ²/(2|r|) = 1 for every row
    lp = build_lp(pairs, 2, 1, bound, np.zeros((2, 1), bool))
    x = np.zeros(lp.n_cols)
    lower = -(lp.matrix @ x) + np.asarray(slacks, float)
    lp = type(lp)(sp.csc_matrix(lp.matrix), -lower + 0.0, lp.col_lower, lp.col_upper,
                  lp.pairs, lp.n, lp.d, lp.step_bound, lp.walls, lp.zero_modes)
    solution = LPSolution(x=x, duals=np.asarray(duals, float), optimal=True, status="Optimal",
                          seconds=0.0, vertex=False, solver="test")
    return lp, solution


def test_ties_in_complementarity_are_decided_by_the_rule():
    """μ̄ = Σ c μ² / Σ c μ = 0.5 here; the bound is 1e-2. A row exactly at q = 0
    (μ b = s μ̄), a row with no dual and no slack, and a row with a dual and a slack below
    zero; twice, in reversed order, with the same answer."""
    duals = [0.5, 0.5, 0.0, 1e-20, 0.0]
    slacks = [1e-2, 0.0, 0.0, -1e-15, 1e-3]
    lp, solution = _one_row_lp(duals, slacks)
    reading = read_complementarity(lp, solution)
    assert reading.dual_scale == pytest.approx(0.5)
    assert reading.contacts.tolist() == [False, True, False, True, False]
    assert reading.score[0] == 0.0 and reading.score[2] == -np.inf
    assert reading.score[3] == np.inf
    reverse = read_complementarity(*_one_row_lp(duals[::-1], slacks[::-1]))
    assert reverse.contacts.tolist() == reading.contacts.tolist()[::-1]


def test_between_flat_walls():
    result = jam(walled_start(64, 3, [0], polydisperse=True), crossover="off")
    assert_jammed_between_walls(result)
    assert result.stop_reason is StopReason.CERTIFIED_NEWTON


def test_in_a_cylinder():
    start = cylinder_start(96, 2, 1, True)
    result = jam(start, crossover="off")
    assert result.converged, result.status
    assert_jammed_in_a_cylinder(result)


@pytest.mark.parametrize("separated", [True, False], ids=["moved apart", "shrunk"])
def test_a_refused_hint_starts_the_lps_where_network_first_got_to(separated, monkeypatch):
    """An LS state at p = 1e5 with its jammed network 20 swaps off as the hint: network
    first refuses it, and the LPs start from the jamming point its rounds reached, at the
    bound of its gap spectrum; they end at the LP path's jamming point. The particles that
    overlap there are moved apart by a small LP, or, when more than `MAX_SEPARATED` overlap
    (here: any), every diameter shrinks by the worst overlap instead."""
    if not separated:
        monkeypatch.setattr(network_first_stage, "MAX_SEPARATED", 0)
        monkeypatch.setattr(network_first_stage, "separate_rattlers",
                            lambda *args: pytest.fail("the separating LP ran"))
    start, source = jammed_from_ls(3, 128, False, pressure=1e5)
    packing = source.packing
    close = NeighborSearch(packing.positions, packing.diameters, packing.box).pairs_within(
        float(packing.diameters.max()) * 1.05)
    contacts = set(map(tuple, source.contacts.tolist()))
    outside = [(int(close.i[k]), int(close.j[k])) for k in np.argsort(close.gaps)
               if (int(close.i[k]), int(close.j[k])) not in contacts]
    hint = source.contacts.copy()
    hint[0:120:6] = outside[:20]
    result = jam(start, network=hint, crossover="off")
    assert_jammed(result)
    assert any(note.startswith("network first: no guessed network was certified")
               for note in result.notes)
    assert any(note.startswith("the LP loop started from the jamming point")
               for note in result.notes)
    assert result.phi == pytest.approx(source.phi, rel=SAME_PHI)


def test_time_limit_stops_cleanly_and_the_checkpoint_resumes(tmp_path):
    start = ls_packing(64, 3, seed=1, pressure=1e7)
    whole = interior(start)
    path = tmp_path / "run.npz"
    stopped = interior(start, time_limit=1e-9, checkpoint=path)
    assert stopped.stop_reason is StopReason.TIME_LIMIT and not stopped.converged
    assert stopped.status.startswith("Stopped at the time limit after 1 LPs")
    assert stopped.iterations == 1 and path.exists()
    resumed = interior(start, checkpoint=path)
    assert_jammed(resumed)
    assert resumed.iterations == whole.iterations
    assert resumed.phi == whole.phi
    with pytest.raises(ValueError, match="time_limit must be > 0"):
        jam(start, time_limit=0)


@pytest.mark.parametrize("bound", [1e-5, 1e-9])
def test_an_lp_near_convergence_is_read_at_the_scale_of_its_bound(ls_jammed, bound):
    """An LP at a jammed packing whose diameters shrank by 1e-12 (gaps and γ ~1e-12 mean
    diameters), with a step bound down to 1e-9: the interior solution's γ is the vertex's,
    and strict complementarity reads exactly the jammed contacts, many decades apart. In
    units of a mean diameter HiGHS's absolute tolerances (1e-10) would be wider than the
    gaps themselves; in units of the bound they are not."""
    packing = ls_jammed.packing
    scale = packing.mean_diameter
    diameters = packing.diameters / scale * (1.0 - 1e-12)
    search = NeighborSearch(packing.positions / scale, diameters, packing.box / scale)
    pinned = np.zeros(packing.n, dtype=bool)
    pinned[0] = True
    lp = build_lp(select_pairs(search, bound), packing.n, packing.d, bound, pinned)
    vertex = solve(lp, HighsOptions())
    centre = solve(lp, HighsOptions(crossover=False))
    assert centre.optimal and not centre.vertex
    assert centre.gamma == pytest.approx(vertex.gamma, rel=1e-6)
    reading = read_complementarity(lp, centre)
    read = {(int(lp.pairs.i[k]), int(lp.pairs.j[k])) for k in np.flatnonzero(reading.contacts)}
    assert read == {tuple(pair) for pair in ls_jammed.contacts.tolist()}
    assert reading.margin > 6


def test_pivots_that_run_out_hand_their_vertex_to_the_next_lp():
    """An LS input (N = 128, d = 4) whose first interior LPs' networks are farther from their
    jamming point than the pivots get in the time of one LP (`INTERIOR_PIVOT_LPS`): each path
    that runs out is recorded, the next LP starts from its vertex, and the run ends certified
    at the same jamming point as the vertex engine."""
    start = generators.lubachevsky_stillinger(generators.diameters.monodisperse(128), d=4,
                                              target_pressure=1e7, seed=1).packing
    result = interior(start)
    assert_jammed(result)
    stages = list(result.history["stage"])
    stopped = [k for k, stage in enumerate(stages[:-1])
               if stage == "pivots" and stages[k + 1] == "lp"]
    assert stopped
    assert any("did not reach a jamming point" in note for note in result.notes)
    vertex = jam(start, network_first="off", crossover="on")
    assert abs(result.phi - vertex.phi) < SAME_PHI * vertex.phi
