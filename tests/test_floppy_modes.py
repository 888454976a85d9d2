"""Closing the floppy modes of a hypostatic network (`calippso.certification.floppy_modes`), on its own and as
the start of network first in `jam`.

The inputs are jammed packings taken back down their own contact manifold: k contacts are
released, and the others are kept closed while Γ falls along the least-displacement floppy
mode (built here by dense least squares, independently of the module). The released
contacts open; the network that remains misses k contacts, and closing its floppy modes with
Γ growing must climb back to the jammed packing.
"""

from __future__ import annotations

import numpy as np
import pytest

from calippso import JammingError, Packing, StopReason, jam
from calippso.certification.floppy_modes import close_floppy_modes
from calippso.geometry.neighbors import NeighborSearch
from calippso.geometry.packing import minimum_image
from calippso.geometry.rattlers import remove_rattlers

from conftest import assert_jammed

#: Jamming points agree to this relative packing fraction.
SAME_PHI = 1e-9
#: The fall in Γ of the backed-down inputs: their released contacts open by ~1e-4 σ, farther
#: than the gap spectrum reads a near-jammed input.
BACK_DOWN = 3e-5
#: Gauss–Newton steps that put the backed-down network back in contact.
PROJECTION_STEPS = 20


def in_mean_diameters(packing: Packing) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    scale = packing.mean_diameter
    return packing.positions / scale, packing.diameters / scale, packing.box / scale


def contact_residual_and_jacobian(positions, diameters, box, network, stable):
    """|r_c|²/σ_c² − 1 of the network and its dense Jacobian in the positions of the stable
    particles but the first, shapes (M,) and (M, d (N_s − 1))."""
    i, j = network[:, 0], network[:, 1]
    vectors = minimum_image(positions[i] - positions[j], box)
    sigma = 0.5 * (diameters[i] + diameters[j])
    n, d = positions.shape
    columns = np.full(n, -1)
    members = np.flatnonzero(stable)
    columns[members[1:]] = np.arange(members.size - 1)
    jacobian = np.zeros((network.shape[0], d * (members.size - 1)))
    for ends, sign in ((i, 1.0), (j, -1.0)):
        for row in np.flatnonzero(columns[ends] >= 0):
            start = d * columns[ends[row]]
            jacobian[row, start:start + d] = sign * 2.0 * vectors[row] / sigma[row] ** 2
    return np.einsum("md,md->m", vectors, vectors) / sigma**2 - 1.0, jacobian


def backed_down(result, k: int, tries: int = 40):
    """The jammed `result` with k contacts released and Γ lowered by `BACK_DOWN` along the
    least-displacement floppy mode of the rest: (positions, diameters, box, network), with
    the released contacts open and no other pair overlapping; None if no choice of k
    contacts within `tries` gives that."""
    positions, diameters, box = in_mean_diameters(result.packing)
    n, d = positions.shape
    contacts = result.contacts
    for seed in range(tries):
        released = np.random.default_rng(seed).choice(contacts.shape[0], k, replace=False)
        network = np.delete(contacts, released, axis=0)
        rattlers, _ = remove_rattlers(n, d, network[:, 0], network[:, 1])
        if (rattlers != result.rattlers).any():
            continue
        stable = ~rattlers
        movable = np.flatnonzero(stable)[1:]
        _, jacobian = contact_residual_and_jacobian(positions, diameters, box, network, stable)
        mode = np.linalg.lstsq(jacobian, -np.ones(network.shape[0]), rcond=None)[0]
        moved = positions.copy()
        moved[movable] += BACK_DOWN * mode.reshape(-1, d)
        shrunk = diameters * np.sqrt(1.0 - BACK_DOWN)
        for _ in range(PROJECTION_STEPS):
            residual, jacobian = contact_residual_and_jacobian(moved, shrunk, box, network,
                                                               stable)
            moved[movable] -= np.linalg.lstsq(jacobian, residual, rcond=None)[0].reshape(-1, d)
        residual, _ = contact_residual_and_jacobian(moved, shrunk, box, network, stable)
        if np.abs(residual).max() > 1e-13:   # the mode curves too much: not a small step
            continue
        search = NeighborSearch(moved, shrunk, box)
        opened = search.pairs_of(contacts[released, 0], contacts[released, 1]).gaps
        close = search.pairs_within(1.01 * shrunk.max())
        others = ~np.isin(close.i * n + close.j, network[:, 0] * n + network[:, 1])
        if opened.min() > 0 and close.gaps[others].min() > 0:
            return moved, shrunk, box, network
    return None


@pytest.fixture(scope="module")
def hypostatic(ls_jammed):
    """The LS packing with 3 of its contacts released and backed down (`backed_down`)."""
    found = backed_down(ls_jammed, 3)
    assert found is not None
    return found


def test_closing_the_floppy_modes_returns_to_the_jamming_point(ls_jammed, hypostatic):
    positions, diameters, box, network = hypostatic
    closure, failure = close_floppy_modes(positions, diameters, box, network[:, 0],
                                          network[:, 1])
    assert closure is not None, failure
    assert len(closure.closed) == 3
    assert closure.refinement.positive
    jammed_positions, jammed_diameters, _ = in_mean_diameters(ls_jammed.packing)
    assert np.mean(closure.refinement.diameters / jammed_diameters) == pytest.approx(
        1.0, abs=SAME_PHI)
    reached = {tuple(pair) for pair in np.column_stack([closure.i, closure.j])}
    assert reached == {tuple(pair) for pair in ls_jammed.contacts}
    assert not (closure.rattlers != ls_jammed.rattlers).any()


def test_jam_closes_a_hypostatic_hint_with_no_lp(ls_jammed, hypostatic):
    positions, diameters, box, network = hypostatic
    scale = ls_jammed.packing.mean_diameter
    start = Packing(positions * scale, diameters * scale, box * scale)
    result = jam(start, network=network, network_first="require")
    assert_jammed(result)
    assert result.stop_reason is StopReason.CERTIFIED_PIVOTS
    assert any("3 floppy mode(s) of the hypostatic network closed" in note
               for note in result.notes)
    assert result.packing.phi == pytest.approx(ls_jammed.packing.phi, rel=SAME_PHI)
    lp_path = jam(start, network_first="off")
    assert result.packing.phi == pytest.approx(lp_path.packing.phi, rel=SAME_PHI)
    assert {tuple(p) for p in result.contacts} == {tuple(p) for p in lp_path.contacts}


def test_without_pivots_a_hypostatic_hint_is_not_settled(ls_jammed, hypostatic):
    positions, diameters, box, network = hypostatic
    scale = ls_jammed.packing.mean_diameter
    start = Packing(positions * scale, diameters * scale, box * scale)
    with pytest.raises(JammingError, match="floppy modes close with pivots only"):
        jam(start, network=network, network_first="require", pivots="off")


def test_an_isostatic_network_has_no_floppy_mode_to_close(ls_jammed):
    positions, diameters, box = in_mean_diameters(ls_jammed.packing)
    contacts = ls_jammed.contacts
    closure, failure = close_floppy_modes(positions, diameters, box, contacts[:, 0],
                                          contacts[:, 1])
    assert closure is None
    assert "not hypostatic" in failure
