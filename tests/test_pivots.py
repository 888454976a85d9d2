"""Contact pivots (`calippso.certification.pivots`): from an isostatic network a few contacts off to the
jamming point, on the exact geometry.

The inputs are jammed packings whose network has k contacts swapped for near pairs: the
Newton point of the swapped network is a vertex below the jamming point (no overlap, some
non-positive forces), and the path must climb back to the original packing, through `jam`
as well as on its own. The path through the restricted LP must end at the same point.
"""

from __future__ import annotations

import numpy as np
import pytest

from calippso import JammingError, Packing, StopReason, jam
from calippso.geometry.neighbors import NeighborSearch
from calippso.certification.newton import refine_isostatic
from calippso.certification.pivots import DEGENERATE_STEP, pivot_to_jamming
from calippso.geometry.rattlers import remove_rattlers

import lattices
from conftest import assert_jammed

#: Near pairs (smallest gaps first) and contacts (smallest forces first) tried when swapping.
NEAR_PAIRS_TRIED = 12
#: Jamming points agree to this relative packing fraction.
SAME_PHI = 1e-9
#: Secant iterations that grow a particle until a pair touches.
TOUCHING_ITERATIONS = 30


@pytest.fixture(scope="module")
def source(ls_jammed):
    """An LS packing at p = 1e7 (d = 3, N = 64) jammed by the LP path."""
    return ls_jammed


def in_mean_diameters(packing: Packing) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    scale = packing.mean_diameter
    return packing.positions / scale, packing.diameters / scale, packing.box / scale


def swapped_networks(result, k: int, wanted: int, overlapping: bool = False) -> list[np.ndarray]:
    """Networks of `result` with k contacts swapped for near pairs (deterministic order), each
    isostatic with the same rattlers, whose Newton point from the jammed positions overlaps
    no other pair (another pair, if `overlapping`) and has a non-positive force; `wanted` of
    them, shape (M, 2)."""
    positions, diameters, box = in_mean_diameters(result.packing)
    n, d = result.packing.n, result.packing.d
    contacts, rattlers = result.contacts, result.rattlers
    search = NeighborSearch(positions, diameters, box)
    close = search.pairs_within(1.2 * diameters.max())
    outside = (~np.isin(close.i * n + close.j, contacts[:, 0] * n + contacts[:, 1])
               & ~rattlers[close.i] & ~rattlers[close.j])
    near = np.flatnonzero(outside)[np.argsort(close.gaps[outside])][:NEAR_PAIRS_TRIED]
    weakest = np.argsort(result.forces)[:NEAR_PAIRS_TRIED]
    rng = np.random.default_rng(k)
    found = []
    for _ in range(400):
        removed = rng.choice(weakest, k, replace=False)
        added = rng.choice(near, k, replace=False)
        keep = np.ones(contacts.shape[0], dtype=bool)
        keep[removed] = False
        network = np.concatenate([contacts[keep],
                                  np.column_stack([close.i[added], close.j[added]])])
        now_rattlers, _ = remove_rattlers(n, d, network[:, 0], network[:, 1])
        if (now_rattlers != rattlers).any():
            continue
        refined = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                                   ~rattlers)
        if refined is None or refined.positive:
            continue
        moved = NeighborSearch(refined.positions, refined.diameters, box)
        pairs = moved.pairs_within(1.01 * refined.diameters.max())
        other = (~np.isin(pairs.i * n + pairs.j, network[:, 0] * n + network[:, 1])
                 & ~rattlers[pairs.i] & ~rattlers[pairs.j])
        if np.any(pairs.gaps[other] < -1e-12) != overlapping:
            continue
        found.append(network)
        if len(found) == wanted:
            break
    assert len(found) == wanted, "the source packing offers too few swapped networks"
    return found


def same_network(a: np.ndarray, b: np.ndarray) -> bool:
    return {tuple(pair) for pair in a.tolist()} == {tuple(pair) for pair in b.tolist()}


def certified_again(path, box: np.ndarray) -> bool:
    """Whether `jam` certifies the path's end on its own (network first, no LP, with the
    path's network as the hint) at the same point: same contacts, φ within `SAME_PHI`."""
    end = Packing(path.refinement.positions, path.refinement.diameters, box)
    network = np.column_stack([path.i, path.j])
    again = jam(end, network=network, network_first="require", pivots="off")
    assert_jammed(again)
    return (again.stop_reason is StopReason.NETWORK_FIRST
            and same_network(again.contacts, network)
            and abs(again.phi - end.phi) < SAME_PHI * end.phi)


@pytest.mark.parametrize("k", [1, 2, 3])
def test_the_path_climbs_to_a_certified_jamming_point(source, k):
    """Γ never decreases, and the end is a jamming point that `jam` certifies by itself.

    The end is the source packing, or another jamming point nearby: the swapped network's
    vertex lies ~1e-3 mean diameters from the source, farther than the gaps of its near
    pairs, and this small packing holds two jamming points 3e-8 apart in φ there; the LP
    loop from the same vertex may end at either."""
    positions, diameters, box = in_mean_diameters(source.packing)
    for network in swapped_networks(source, k, wanted=2):
        start = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                                 ~source.rattlers)
        path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0],
                                         network[:, 1], source.rattlers, refined=start)
        assert path is not None and path.jammed, failure
        assert path.pivots >= 1 and path.refinement.positive
        assert all(swap.growth >= 0 for swap in path.swaps)   # Γ never decreases
        assert path.refinement.diameters[0] >= start.diameters[0]
        np.testing.assert_array_equal(path.rattlers, source.rattlers)
        assert certified_again(path, box)


def test_a_single_swap_returns_to_the_source(source):
    positions, diameters, box = in_mean_diameters(source.packing)
    network = swapped_networks(source, 1, wanted=1)[0]
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers)
    assert path is not None and path.jammed, failure
    assert same_network(np.column_stack([path.i, path.j]), source.contacts)
    assert np.allclose(path.refinement.diameters / diameters, 1.0, rtol=0, atol=SAME_PHI)


@pytest.mark.parametrize("k", [1, 2])
def test_jam_certifies_a_hint_a_few_contacts_off(source, k):
    """The input is the Newton point of a swapped network and the hint is that network:
    pivots repair it with no LP. For a single swap the LP loop from the same input (network
    first off) reaches the same jamming point (the source packing, or the jamming point next
    to it, `test_the_path_climbs_to_a_certified_jamming_point`); two swaps move the input so
    far (~1e-3 mean diameters) that the two may end at different certified points."""
    positions, diameters, box = in_mean_diameters(source.packing)
    for network in swapped_networks(source, k, wanted=2):
        vertex = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                                  ~source.rattlers)
        start = Packing(vertex.positions, vertex.diameters, box)
        pivoted = jam(start, network=network, network_first="require")
        assert pivoted.stop_reason is StopReason.CERTIFIED_PIVOTS
        assert pivoted.iterations == 0
        assert_jammed(pivoted)
        assert pivoted.force_balance < 1e-12
        assert list(pivoted.history["stage"]) == ["guess", "pivots", "newton"]
        assert pivoted.history["pivots"][1] >= 1
        assert any("contact pivot" in note for note in pivoted.notes)

        if k == 1:
            lp_loop = jam(start, network_first="off")
            np.testing.assert_array_equal(pivoted.contacts, lp_loop.contacts)
            assert abs(pivoted.phi - lp_loop.phi) < SAME_PHI * lp_loop.phi


def vertex_touching(positions, diameters, box, network, rattlers, pair):
    """The Newton point of `network` with particle pair[0] grown until `pair` (outside the
    network) touches there (secant iterations on its growth); its Refinement, or None if the
    secant does not reach a gap of round-off."""
    a, b = pair

    def solved(growth: float):
        grown = diameters.copy()
        grown[a] *= 1.0 + growth
        refined = refine_isostatic(positions, grown, box, network[:, 0], network[:, 1],
                                   ~rattlers)
        moved = NeighborSearch(refined.positions, refined.diameters, box)
        return moved.pairs_of(np.array([a]), np.array([b])).gaps[0], refined

    low, (low_gap, _) = 0.0, solved(0.0)
    high = 1e-4
    high_gap, refined = solved(high)
    for _ in range(TOUCHING_ITERATIONS):
        if abs(high_gap) < 1e-15 or high_gap == low_gap:
            break
        step = high_gap * (high - low) / (high_gap - low_gap)
        low, low_gap, high = high, high_gap, high - step
        high_gap, refined = solved(high)
    return refined if abs(high_gap) < 1e-15 else None


def test_a_degenerate_pivot_gains_nothing_and_the_path_goes_on(source):
    """A vertex where a pair outside the network touches (a particle grown until it does):
    that pair closes at a zero step, Γ does not grow, and the path still ends certified."""
    positions, diameters, box = in_mean_diameters(source.packing)
    n = source.packing.n
    for network in swapped_networks(source, 1, wanted=3):
        start = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                                 ~source.rattlers)
        moved = NeighborSearch(start.positions, start.diameters, box)
        near = moved.pairs_within(1.05 * start.diameters.max())
        outside = np.flatnonzero(~np.isin(near.i * n + near.j,
                                          network[:, 0] * n + network[:, 1]))
        for q in outside[np.argsort(near.gaps[outside])][:6]:
            pair = (int(near.i[q]), int(near.j[q]))
            vertex = vertex_touching(positions, diameters, box, network, source.rattlers, pair)
            if vertex is None:
                continue
            path, _ = pivot_to_jamming(vertex.positions, vertex.diameters, box, network[:, 0],
                                       network[:, 1], source.rattlers, refined=vertex)
            if path is None or not path.jammed or not path.degenerate:
                continue
            first = path.swaps[0]
            assert first.closed == pair and first.growth <= DEGENERATE_STEP
            assert all(swap.growth >= 0 for swap in path.swaps)
            assert path.refinement.positive
            try:
                assert certified_again(path, box)
            except JammingError as error:   # the grown particle left another pair touching
                assert "touch (a hyperstatic packing)" in str(error)
                continue
            return
    pytest.fail("no degenerate pivot was made")


def test_a_rattler_leaves_and_rejoins_the_network(source):
    """A release leaves a particle with d contacts (a rattler); along the floppy mode its cage
    closes on it, and it joins the network again with the d + 1 pairs of its cage. The path
    ends certified, with the source's rattlers (none)."""
    positions, diameters, box = in_mean_diameters(source.packing)
    rejoining = []
    for network in swapped_networks(source, 2, wanted=4):
        path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0],
                                         network[:, 1], source.rattlers)
        assert path is not None and path.jammed, failure
        if any(swap.rejoined for swap in path.swaps):
            rejoining.append(path)
    assert rejoining, "no path made a rattler rejoin"
    for path in rejoining:
        assert any(swap.new_rattlers for swap in path.swaps)
        np.testing.assert_array_equal(path.rattlers, source.rattlers)
        assert all(swap.growth >= 0 for swap in path.swaps)
        assert certified_again(path, box)


def test_a_network_that_overlaps_another_pair_is_refused(source):
    """The path starts from a feasible vertex only: an overlap at the start is reported."""
    positions, diameters, box = in_mean_diameters(source.packing)
    network = swapped_networks(source, 1, wanted=1, overlapping=True)[0]
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers)
    assert path is None and "overlap" in failure


@pytest.mark.parametrize("crystal", [lattices.fcc(2), lattices.triangular(4)],
                         ids=["fcc", "triangular"])
def test_a_crystal_falls_back_cleanly(crystal):
    """A crystal at contact is degenerate: every pair outside an isostatic subset of its
    touching pairs already touches. Pivots cannot certify it (a touching pair is left out),
    and jam ends exactly as with pivots off, by the LP loop."""
    with pytest.raises(JammingError):
        jam(crystal, network_first="require")
    result = jam(crystal)
    off = jam(crystal, pivots="off")
    assert result.converged and result.isostaticity_gap >= 0
    assert result.iterations == off.iterations >= 1
    np.testing.assert_array_equal(result.contacts, off.contacts)
    assert result.phi == off.phi


def test_pivots_in_the_lp_loop_are_refused_with_the_reason():
    """pivots='always' is not a mode: the error says it was removed and names the default."""
    with pytest.raises(ValueError, match="'always'.*removed.*'network_first'"):
        jam(lattices.fcc(2), pivots="always")


def test_a_release_that_leaves_a_singular_network_gives_way_to_the_next(source, monkeypatch):
    """When the most negative contact's release leaves a singular network (simulated: its
    floppy mode is refused), the next non-positive contact leaves instead, and the path
    still reaches a certified jamming point."""
    from calippso.certification.pivots import path as pivot_path

    positions, diameters, box = in_mean_diameters(source.packing)
    for network in swapped_networks(source, 2, wanted=2) + swapped_networks(source, 3,
                                                                            wanted=2):
        start = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                                 ~source.rattlers)
        if np.count_nonzero(start.forces <= 0) >= 2:
            break
    else:
        pytest.skip("no swapped network with two non-positive forces")
    most_negative = tuple(network[np.argmin(start.forces)])
    real_floppy_mode, calls = pivot_path._floppy_mode, []

    def singular_first(*args, **kwargs):
        calls.append(1)
        return None if len(calls) == 1 else real_floppy_mode(*args, **kwargs)

    monkeypatch.setattr(pivot_path, "_floppy_mode", singular_first)
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers, refined=start)
    assert path is not None and path.jammed, failure
    assert path.swaps[0].released != most_negative
    assert certified_again(path, box)


def test_network_first_stops_when_its_pivot_budget_is_spent(source, monkeypatch):
    """The stage's pivots share one budget of wall time (`STAGE_PIVOT_FACTORIZATIONS` times
    its first factorisation). A hint whose path needs pivots is certified by them with the
    default budget; with none the stage refuses it, naming the budget, and the LP loop
    certifies the input instead."""
    from calippso.certification import network_first

    positions, diameters, box = in_mean_diameters(source.packing)
    network = swapped_networks(source, 3, wanted=1)[0]
    vertex = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                              ~source.rattlers)
    start = Packing(vertex.positions, vertex.diameters, box)
    pivoted = jam(start, network=network, network_first="require")
    assert int(np.nansum(pivoted.history["pivots"])) >= 1

    monkeypatch.setattr(network_first, "STAGE_PIVOT_FACTORIZATIONS", 0)
    with pytest.raises(JammingError, match="pivots are spent"):
        jam(start, network=network, network_first="require")
    by_lps = jam(start, network=network)
    assert by_lps.iterations >= 1
    assert_jammed(by_lps)


def test_the_path_records_each_pivot_and_its_linear_algebra(source):
    """Every swap carries its wall time and the forces still non-positive after it (none after
    the last), and the path's tally counts at least one factorisation and solve per pivot."""
    positions, diameters, box = in_mean_diameters(source.packing)
    network = swapped_networks(source, 3, wanted=1)[0]
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers)
    assert path is not None and path.jammed, failure
    assert all(swap.seconds > 0 for swap in path.swaps)
    assert path.swaps[-1].non_positive == 0
    assert sum(swap.seconds for swap in path.swaps) <= path.seconds
    assert path.cost.factorizations >= 1 and path.cost.solves >= path.pivots
    assert 0 < path.cost.factorize_seconds + path.cost.solve_seconds <= path.seconds
    assert path.median_pivot_seconds > 0


def test_a_path_stops_at_its_time_limit_where_it_got_to(source):
    """A path out of pivots or out of time ends at the vertex it reached, not jammed, with
    the reason; with its time spent before the first pivot, that vertex is the start."""
    positions, diameters, box = in_mean_diameters(source.packing)
    network = swapped_networks(source, 3, wanted=1)[0]
    start = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                             ~source.rattlers)
    path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                     source.rattlers, refined=start, max_pivots=1)
    assert path is not None and not path.jammed and path.pivots == 1
    assert "1 pivots" in failure
    stopped, why = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                    source.rattlers, refined=start, time_limit=1e-9)
    assert "s of pivots" in why
    assert stopped is not None and not stopped.jammed and stopped.pivots == 0
    assert stopped.refinement.diameters[0] >= start.diameters[0]


def test_one_factorisation_serves_the_pivots_that_follow(source):
    """The floppy mode is read from the vertex's own Jacobian (J u = e_c), whose factors
    serve the next pivots with their swapped rows: a path of several pivots makes fewer
    factorisations than pivots, and ends at the same jamming point as with new factors at
    every pivot (`MAX_ROW_SWAPS` = 0)."""
    from calippso.certification.pivots import vertex

    positions, diameters, box = in_mean_diameters(source.packing)
    for network in swapped_networks(source, 3, wanted=2):
        start = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                                 ~source.rattlers)
        path, failure = pivot_to_jamming(positions, diameters, box, network[:, 0],
                                         network[:, 1], source.rattlers, refined=start)
        assert path is not None and path.jammed, failure
        if path.pivots >= 3:
            break
    assert path.pivots >= 3
    assert path.cost.factorizations < path.pivots
    saved = vertex.MAX_ROW_SWAPS
    vertex.MAX_ROW_SWAPS = 0
    try:
        fresh, _ = pivot_to_jamming(positions, diameters, box, network[:, 0], network[:, 1],
                                    source.rattlers, refined=start)
    finally:
        vertex.MAX_ROW_SWAPS = saved
    assert fresh.cost.factorizations > path.cost.factorizations
    assert same_network(np.column_stack([path.i, path.j]),
                        np.column_stack([fresh.i, fresh.j]))
    np.testing.assert_allclose(path.refinement.diameters, fresh.refinement.diameters,
                               rtol=SAME_PHI)


def test_a_degenerate_cycle_is_caught_and_bland_chooses_the_leaving_contact(source,
                                                                               monkeypatch):
    """A network built to cycle: two vertices A and B of equal Γ, each with a non-positive
    force, where every pivot from one leads to the other with no growth (a degenerate pivot,
    simulated). On the degenerate stretch the leaving contact is the non-positive one of
    smallest pair key (Bland's rule), and the path ends at its return to A, saying so,
    instead of cycling."""
    from calippso.certification.pivots import path as pivot_path
    from calippso.certification.pivots.vertex import Swap, Vertex

    positions, diameters, box = in_mean_diameters(source.packing)
    stable = ~source.rattlers
    vertices = []
    for network in swapped_networks(source, 2, wanted=4):
        refined = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                                   stable)
        if np.count_nonzero(refined.forces <= 0) >= 2:
            vertices.append(Vertex(network[:, 0].astype(np.int64),
                                   network[:, 1].astype(np.int64), stable, refined))
    if len(vertices) < 2:
        pytest.skip("fewer than two swapped networks with two non-positive forces")
    first, second = vertices[:2]
    released = []

    def degenerate_pivot(search, vertex, leaving, attached=False):
        released.append((vertex, leaving))
        other = second if np.array_equal(vertex.keys, first.keys) else first
        pair = (int(vertex.i[leaving]), int(vertex.j[leaving]))
        return (other, Swap(pair, (int(other.i[0]), int(other.j[0])), 0.0, 0)), ""

    monkeypatch.setattr(pivot_path, "_pivot", degenerate_pivot)
    path, failure = pivot_to_jamming(positions, diameters, box, first.i, first.j,
                                     source.rattlers, refined=first.refinement)
    assert "cycling" in failure
    # A -> B is taken; B -> A returns to a network seen since Γ last grew: the path ends at B
    assert path is not None and not path.jammed and path.degenerate == path.pivots == 1
    assert len(released) == 2
    np.testing.assert_array_equal(np.sort(path.i * len(stable) + path.j), np.sort(second.keys))
    for vertex, leaving in released[1:]:   # after the first degenerate pivot: Bland's rule
        forces = vertex.refinement.forces
        non_positive = np.flatnonzero(forces <= 0)
        assert leaving == non_positive[np.argmin(vertex.keys[non_positive])]


def test_a_run_shows_the_pivot_path_as_it_goes(source, monkeypatch, capsys):
    """After every pivot the callback gets a provisional record (stage "pivot"): the pivots so
    far, the forces still non-positive (none after the last), the pair released and closed,
    and the vertex's packing; the history keeps only the path's one "pivots" record. A
    verbose run prints a line per pivot when `PIVOT_PRINT_SECONDS` allows."""
    from calippso.stages import newton_stage

    monkeypatch.setattr(newton_stage, "PIVOT_PRINT_SECONDS", 0.0)
    positions, diameters, box = in_mean_diameters(source.packing)
    network = swapped_networks(source, 3, wanted=1)[0]
    vertex = refine_isostatic(positions, diameters, box, network[:, 0], network[:, 1],
                              ~source.rattlers)
    start = Packing(vertex.positions, vertex.diameters, box)
    seen = []
    result = jam(start, network=network, network_first="require", verbose=True,
                 callback=seen.append)
    ticks = [record for record in seen if record["stage"] == "pivot"]
    taken = int(np.nansum(result.history["pivots"]))
    assert taken >= 1 and "pivot" not in list(result.history["stage"])
    assert [tick["pivots"] for tick in ticks] == list(range(1, taken + 1))
    assert ticks[-1]["non_positive"] == 0
    assert all(tick["packing"].n == start.n and len(tick["released"]) == 2 for tick in ticks)
    assert capsys.readouterr().out.count(" pivot ") == taken
