"""Pairs that touch outside the contact network (`calippso.geometry.touching`), built on purpose.

A touching pair with zero force is a codimension-one event: from a jammed packing, the
network's contact equations plus "the nearest open pair touches" are solved with one
diameter and Γ as unknowns. The network still carries the certificate there (its forces
move by O(gap) and stay positive), and the new pair touches with zero force. The result must
report it (`touching_pairs`, the summary, the run record, the analysis) and keep it out of
the contacts and out of the gaps.
"""

from __future__ import annotations

import numpy as np
import pytest

from calippso import JammingResult, Packing, jam
from calippso.analysis import contact_statistics, gaps, run_record
from calippso.certification.certificate import certify_network
from calippso.geometry.contact_network import ContactNetwork
from calippso.geometry.packing import minimum_image
from calippso.geometry.touching import TOUCHING_GAP, touching_outside_network
from conftest import assert_jammed

#: Newton on the augmented contact equations stops below this residual (|r|² − Γσ², σ ~ 1).
RESIDUAL = 1e-15


def _touch_one_more_pair(result: JammingResult) -> tuple[Packing, tuple[int, int]]:
    """`result`'s packing moved so that its nearest open pair of stable particles touches,
    every contact still touching: positions of the stable particles (one pinned), Γ and the
    diameter of one particle of the pair are the unknowns (as many as the equations)."""
    packing = result.packing
    n, d = packing.n, packing.d
    stable = ~result.rattlers
    contacts = result.contacts
    candidates = touching_outside_network(packing, contacts, result.rattlers, gap=0.05)
    nearest = int(np.argmin(candidates.pair_gaps))
    pair = tuple(int(k) for k in candidates.pairs[nearest])
    rows = np.vstack([contacts, pair])
    moving = np.flatnonzero(stable)[1:]              # the first stable particle is pinned
    column = -np.ones(n, dtype=np.int64)
    column[moving] = np.arange(moving.size)
    n_positions = d * moving.size
    positions = packing.positions.copy()
    diameters = packing.diameters.copy()
    grown = pair[0]
    gamma = 1.0
    for _ in range(30):
        r = minimum_image(positions[rows[:, 0]] - positions[rows[:, 1]], packing.box)
        sigma = 0.5 * (diameters[rows[:, 0]] + diameters[rows[:, 1]])
        residual = np.einsum("ij,ij->i", r, r) - gamma * sigma**2
        if np.abs(residual).max() < RESIDUAL:
            break
        jacobian = np.zeros((rows.shape[0], n_positions + 2))
        for sign, end in ((2.0, 0), (-2.0, 1)):
            cols = column[rows[:, end]]
            for axis in range(d):
                hit = cols >= 0
                jacobian[np.flatnonzero(hit), d * cols[hit] + axis] += sign * r[hit, axis]
        jacobian[:, n_positions] = -sigma**2
        touches_grown = (rows[:, 0] == grown) | (rows[:, 1] == grown)
        jacobian[touches_grown, n_positions + 1] = -gamma * sigma[touches_grown]
        step = np.linalg.solve(jacobian, -residual)
        positions[moving] += step[:n_positions].reshape(-1, d)
        gamma += step[n_positions]
        diameters[grown] += step[n_positions + 1]
    else:
        raise AssertionError("Newton on the augmented contact equations did not converge")
    return Packing(positions, diameters * np.sqrt(gamma), packing.box), pair


@pytest.fixture(scope="module")
def touching_result(ls_jammed):
    """The certificate of `ls_jammed`'s own network on the packing with one more touching
    pair: a certified result whose network leaves that pair out."""
    packing, pair = _touch_one_more_pair(ls_jammed)
    contacts = ls_jammed.contacts
    network = ContactNetwork(contacts[:, 0], contacts[:, 1], np.zeros(len(contacts)),
                             ls_jammed.rattlers.copy(), float("nan"), "none", from_lp=False)
    certified, why = certify_network(packing.positions, packing.diameters, packing.box,
                                     network)
    assert certified is not None, why
    forces = certified.network.forces
    result = JammingResult(
        packing=Packing(certified.positions, certified.diameters, packing.box),
        contacts=contacts, forces=forces / forces.mean(), rattlers=ls_jammed.rattlers.copy(),
        converged=True, status="Jammed: the contact network certified",
        iterations=0, force_balance=certified.balance,
        dual_normalization=certified.network.normalization, solver="none")
    return result, pair


def test_the_built_pair_touches_outside_a_certified_network(touching_result):
    result, pair = touching_result
    assert_jammed(result)
    assert result.touching_pairs.tolist() == [list(pair)]
    touching = result.touching
    assert abs(touching.pair_gaps[0]) <= TOUCHING_GAP
    assert touching.walls.shape == (0, 2)


def test_reported_in_the_summary_record_and_analysis(touching_result):
    result, pair = touching_result
    summary = result.summary()
    assert "touching outside the network: 1 pair(s)" in summary
    assert f"would be {result.isostaticity_gap + 1:+d}" in summary
    assert run_record(result)["n_touching"] == 1
    assert contact_statistics(result).n_touching == 1
    # neither a contact nor a gap: the analysis leaves it out of both
    assert contact_statistics(result).n_contacts == result.n_contacts
    h = gaps(result)
    assert h.size and h.min() > TOUCHING_GAP


def test_a_jammed_packing_without_degenerate_pairs_reports_none(ls_jammed):
    assert ls_jammed.touching_pairs.shape == (0, 2)
    assert "touching outside" not in ls_jammed.summary()
    assert run_record(ls_jammed)["n_touching"] == 0


def test_jam_loses_no_touching_pair(touching_result):
    """Whatever network jam reads at the degenerate point, every touching pair of stable
    particles is either a contact or reported as touching outside the network."""
    result, _ = touching_result
    again = jam(result.packing)
    assert again.converged, again.status
    packing = again.packing
    everything = touching_outside_network(packing, np.zeros((0, 2), np.int64), again.rattlers)
    reported = {tuple(p) for p in again.touching_pairs.tolist()}
    contacts = {tuple(p) for p in again.contacts.tolist()}
    assert {tuple(p) for p in everything.pairs.tolist()} == reported | contacts
    if reported:   # the verdict itself says how the count changes
        assert (f"{len(reported)} more pair(s) touch outside the network with zero force"
                in again.status)
        assert f"would be {again.isostaticity_gap + len(reported):+d}" in again.status
