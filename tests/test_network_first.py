"""Network first: a near-jammed input's own contact network, certified by Newton with no LP.

A near-jammed input is a jammed packing with every diameter shrunk by 2e-7 and every position
moved by 1e-9. The network-first stage must give exactly what the LP path gives from the same
input (same contacts, φ_J within 1e-10, forces within 1e-8), and an input that only looks
near-jammed (a crystal, a network with a negative self-stress, one whose jamming point would
overlap another pair) must fall back to the LPs and end as the LP path does.
"""

from __future__ import annotations

import numpy as np
import pytest

import generators
from calippso import JammingError, Packing, StopReason, jam
from calippso.certification.network_guess import candidate_networks
from calippso.geometry.neighbors import NeighborSearch

import lattices
from conftest import assert_jammed

#: Relative shrink of the diameters, and size of the random displacements (mean diameters),
#: that make a near-jammed input from a jammed packing.
SHRINK = 2e-7
MOVE = 1e-9


def near_jammed(packing: Packing, seed: int = 0) -> Packing:
    """`packing` shrunk by `SHRINK` and moved by `MOVE` (seeded Gaussian displacements)."""
    rng = np.random.default_rng(seed)
    moved = packing.positions + MOVE * packing.mean_diameter * rng.standard_normal(
        packing.positions.shape)
    return Packing(moved, packing.diameters * (1.0 - SHRINK), packing.box)


def jammed_from_ls(d: int, n: int, polydisperse: bool, pressure: float = 1e7):
    """An LS packing compressed to `pressure` (log-normal sizes of width 0.2 if polydisperse),
    and its jammed packing by the LP path (network first off)."""
    sizes = (generators.diameters.lognormal(n, 0.2, seed=d) if polydisperse
             else generators.diameters.monodisperse(n))
    start = generators.lubachevsky_stillinger(sizes, d=d, target_pressure=pressure,
                                              seed=d).packing
    return start, jam(start, network_first="off")


def assert_same_jamming_point(result, reference) -> None:
    """The same contacts and rattlers, φ_J within 1e-10 and forces within 1e-8."""
    np.testing.assert_array_equal(result.contacts, reference.contacts)
    np.testing.assert_array_equal(result.rattlers, reference.rattlers)
    assert abs(result.phi - reference.phi) < 1e-10
    np.testing.assert_allclose(result.forces, reference.forces, rtol=0, atol=1e-8)


CASES = [
    pytest.param(2, 64, True, id="d2-poly"),
    pytest.param(3, 64, False, id="d3-mono"),
    pytest.param(3, 64, True, id="d3-poly"),
    pytest.param(4, 64, False, id="d4-mono"),
    pytest.param(4, 256, True, id="d4-poly", marks=pytest.mark.slow),
    pytest.param(5, 256, False, id="d5-mono", marks=pytest.mark.slow),
]


@pytest.mark.parametrize("d, n, polydisperse", CASES)
def test_certified_network_is_what_the_lp_path_gives(d, n, polydisperse):
    _, source = jammed_from_ls(d, n, polydisperse)
    start = near_jammed(source.packing)
    first = jam(start)
    lp_only = jam(start, network_first="off", newton=False)
    assert first.iterations == 0 and first.converged
    assert list(first.history["stage"]) == ["guess", "newton"]
    assert first.stop_reason is StopReason.NETWORK_FIRST
    assert first.solver == "none"
    assert_jammed(first)
    assert first.force_balance < 1e-12
    assert lp_only.iterations >= 1 and lp_only.isostatic
    assert_same_jamming_point(first, lp_only)
    # the jamming point of the source packing, found again
    np.testing.assert_array_equal(first.contacts, source.contacts)
    assert abs(first.phi - source.phi) < 1e-10


def test_rattlers_are_kept_out_of_the_certified_network():
    _, source = jammed_from_ls(2, 64, True)
    assert source.rattlers.sum() >= 3
    first = jam(near_jammed(source.packing))
    assert first.iterations == 0
    np.testing.assert_array_equal(first.rattlers, source.rattlers)
    assert not np.isin(np.flatnonzero(first.rattlers), first.contacts).any()


@pytest.fixture(scope="module")
def d3_source():
    return jammed_from_ls(3, 64, False)


def test_a_hint_is_tried_first(d3_source):
    _, source = d3_source
    result = jam(near_jammed(source.packing), network=source.contacts)
    assert result.iterations == 0
    assert any(note.startswith("the input's own contact network (given as a hint")
               for note in result.notes)
    np.testing.assert_array_equal(result.contacts, source.contacts)


def test_a_hint_with_extra_near_contacts_is_settled(d3_source):
    """Two extra pairs, the nearest non-contacts: the restricted LP leaves them open."""
    _, source = d3_source
    start = near_jammed(source.packing)
    search = NeighborSearch(start.positions, start.diameters, start.box)
    close = search.pairs_within(float(start.diameters.max()) * 1.2)
    contact_keys = source.contacts[:, 0] * start.n + source.contacts[:, 1]
    outside = ~np.isin(close.i * start.n + close.j, contact_keys)
    stable = ~source.rattlers[close.i] & ~source.rattlers[close.j]
    candidates = np.flatnonzero(outside & stable)
    extra = candidates[np.argsort(close.gaps[candidates])[:2]]
    hint = np.concatenate([source.contacts, np.column_stack([close.i[extra], close.j[extra]])])
    result = jam(start, network=hint)
    assert result.iterations == 0
    assert any("near pair(s) left open" in note for note in result.notes)
    np.testing.assert_array_equal(result.contacts, source.contacts)


@pytest.mark.parametrize("crystal", [lattices.fcc(2), lattices.bcc(2), lattices.triangular(4)],
                         ids=["fcc", "bcc", "triangular"])
def test_a_crystal_falls_back_to_the_lps(crystal):
    """A crystal at contact: every gap is zero, so an isostatic subset of the touching pairs
    is a candidate. It is refused (its Jacobian is singular, or a force is not positive; a
    certified subset would be refused too, for leaving touching pairs out), and the LPs end
    as without the stage (FCC and triangular stay hyperstatic crystals; BCC is not rigid and
    the LPs move it)."""
    search = NeighborSearch(crystal.positions, crystal.diameters, crystal.box)
    assert all(candidate.pairs.gaps.max() < 1e-14
               for candidate in candidate_networks(search, crystal.d))
    result = jam(crystal)
    off = jam(crystal, network_first="off")
    assert result.history["stage"][1] == "lp"
    assert any(note.startswith("network first: no guessed network was certified")
               for note in result.notes)
    assert result.isostaticity_gap == off.isostaticity_gap >= 0
    assert result.iterations == off.iterations >= 1
    np.testing.assert_array_equal(result.contacts, off.contacts)
    assert result.phi == off.phi


@pytest.fixture(scope="module")
def compressed():
    """An LS state at reduced pressure 1e5 (no isostatic network in its gap spectrum), its
    LP-path result, and wrong hints: its jammed network with one contact swapped for one of
    the nearest non-contacts."""
    start, source = jammed_from_ls(3, 64, False, pressure=1e5)
    packing = source.packing
    search = NeighborSearch(packing.positions, packing.diameters, packing.box)
    close = search.pairs_within(float(packing.diameters.max()) * 1.05)
    keys = set(map(tuple, source.contacts.tolist()))
    outside = [(int(close.i[k]), int(close.j[k])) for k in np.argsort(close.gaps)
               if (int(close.i[k]), int(close.j[k])) not in keys
               and not source.rattlers[close.i[k]] and not source.rattlers[close.j[k]]]
    swapped = []
    for contact, pair in zip((0, 40, 80), outside):
        hint = source.contacts.copy()
        hint[contact] = pair
        swapped.append(hint)
    return start, jam(start, network_first="off"), swapped


def test_an_lp_start_has_no_candidate_network(compressed):
    start, off, _ = compressed
    with pytest.raises(JammingError, match="network_first='require': no network guessed"):
        jam(start, network_first="require")
    result = jam(start)
    assert result.iterations == off.iterations
    np.testing.assert_array_equal(result.contacts, off.contacts)


def test_a_hint_one_swap_off_is_settled_to_the_lp_result(compressed):
    """From a compressed state (gaps ~1e-5) with the jammed network one swap off: the
    restricted LP and Newton rounds repair it, and the result is the LP path's."""
    start, off, swapped = compressed
    for hint in swapped:
        result = jam(start, network=hint, network_first="require")
        assert result.iterations == 0 and result.solver == "none"
        assert_jammed(result)
        assert result.force_balance < 1e-12
        assert_same_jamming_point(result, off)


def test_a_hint_too_far_from_its_jamming_point_falls_back_to_the_lps():
    """An LS state at reduced pressure 1e3 (gaps ~1e-3) with its own jammed network as the
    hint: too far to settle without LPs, so the loop runs and ends exactly as without the
    stage."""
    start, off = jammed_from_ls(3, 64, False, pressure=1e3)
    result = jam(start, network=off.contacts)
    assert result.history["stage"][0] == "guess" and result.iterations == off.iterations
    assert any(note.startswith("network first: no guessed network was certified (hint: ")
               for note in result.notes)
    np.testing.assert_array_equal(result.contacts, off.contacts)
    assert result.phi == pytest.approx(off.phi, rel=1e-14)
    np.testing.assert_allclose(result.forces, off.forces, rtol=1e-12)
    assert result.isostatic and result.force_balance < 1e-12


@pytest.mark.parametrize("network, message", [
    (np.array([1, 2, 3]), r"\(M, 2\) integer array"),
    (np.array([[0.0, 1.0]]), r"\(M, 2\) integer array"),
    (np.array([[0, 10_000]]), r"indices outside \[0, 64\)"),
    (np.array([[3, 3]]), "pairs a particle with itself"),
])
def test_a_malformed_hint_is_refused(d3_source, network, message):
    _, source = d3_source
    with pytest.raises(ValueError, match=message):
        jam(source.packing, network=network)


def test_network_first_off_never_guesses(d3_source):
    _, source = d3_source
    result = jam(near_jammed(source.packing), network_first="off")
    assert "guess" not in set(result.history["stage"]) and result.iterations >= 1


def test_unknown_mode_is_refused():
    with pytest.raises(ValueError, match="unknown network_first 'maybe'"):
        jam(lattices.fcc(2), network_first="maybe")


@pytest.mark.parametrize("d, sizes", [
    pytest.param(2, generators.diameters.lognormal(256, 0.2, seed=2), id="d2-poly"),
    pytest.param(3, generators.diameters.monodisperse(256), id="d3-mono"),
])
def test_a_soft_quench_is_jammed_with_no_lp(d, sizes):
    """The quench's overlap network as the hint: the result is the LP path's, with no LP."""
    quench = generators.soft_quench(sizes, d, seed=1)
    first = jam(quench.packing, network=quench.contacts)
    lp_only = jam(quench.packing, network_first="off", newton=False)
    assert first.iterations == 0 and lp_only.iterations >= 1
    assert_jammed(first)
    assert first.force_balance < 1e-12
    assert_same_jamming_point(first, lp_only)
