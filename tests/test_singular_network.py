"""A singular network handed to network first: isostatic by count, singular by rank.

The input is a jammed packing whose network is edited: a particle p with d + 1 contacts
keeps only d − 1 of them, so that it can roll on them (a floppy mode), and the two near
pairs nearest to contact elsewhere join the network, one more than the rest of it can hold
(a self-stress). The count is isostatic, N_c = d (N_s − 1) + 1, the Jacobian singular:
Newton and the contact pivots refuse it; network first, which reads the hint with its near
pairs, lets the restricted LP choose the jammed network among them instead.
"""

from __future__ import annotations

import numpy as np
import pytest

from calippso import StopReason, jam
from calippso.certification.newton import NEWTON_FAILED, network_jacobian, refine_isostatic
from calippso.certification.pivots import pivot_to_jamming
from calippso.geometry.neighbors import NeighborSearch
from calippso.geometry.packing import minimum_image

from conftest import assert_jammed
from test_pivots import in_mean_diameters

#: The smallest singular value of a singular Jacobian, relative to the largest, is round-off;
#: the next one is not (the rank lacks exactly one).
SINGULAR = 1e-13
REGULAR = 1e-6
#: Jamming points that agree in φ to this relative precision are the same.
SAME_PHI = 1e-9


def singular_network(result) -> np.ndarray:
    """The network of `result` with two contacts of its first particle with d + 1 contacts
    left out and the two pairs nearest to contact away from it added, shape (M, 2)."""
    positions, diameters, box = in_mean_diameters(result.packing)
    contacts, n, d = result.contacts, result.packing.n, result.packing.d
    counts = np.bincount(contacts.ravel(), minlength=n)
    p = int(np.flatnonzero((counts == d + 1) & ~result.rattlers)[0])
    own = np.flatnonzero((contacts[:, 0] == p) | (contacts[:, 1] == p))
    kept = np.delete(contacts, own[:2], axis=0)
    close = NeighborSearch(positions, diameters, box).pairs_within(1.2 * diameters.max())
    outside = (~np.isin(close.i * n + close.j, contacts[:, 0] * n + contacts[:, 1])
               & (close.i != p) & (close.j != p)
               & ~result.rattlers[close.i] & ~result.rattlers[close.j])
    nearest = np.flatnonzero(outside)[np.argsort(close.gaps[outside], kind="stable")[:2]]
    return np.concatenate([kept, np.column_stack([close.i[nearest], close.j[nearest]])])


@pytest.fixture(scope="module")
def singular(ls_jammed):
    return singular_network(ls_jammed)


def test_the_network_is_isostatic_by_count_and_singular_by_rank(ls_jammed, singular):
    positions, diameters, box = in_mean_diameters(ls_jammed.packing)
    d, stable = ls_jammed.packing.d, ~ls_jammed.rattlers
    assert singular.shape[0] == d * (int(stable.sum()) - 1) + 1
    vectors = minimum_image(positions[singular[:, 0]] - positions[singular[:, 1]], box)
    sigma = 0.5 * (diameters[singular[:, 0]] + diameters[singular[:, 1]])
    jacobian = network_jacobian(vectors, sigma, singular[:, 0], singular[:, 1], stable)
    values = np.linalg.svd(jacobian.toarray(), compute_uv=False)
    assert values[-1] < SINGULAR * values[0] and values[-2] > REGULAR * values[0]
    assert refine_isostatic(positions, diameters, box, singular[:, 0], singular[:, 1],
                            stable) is None


def test_the_pivots_refuse_a_singular_network(ls_jammed, singular):
    positions, diameters, box = in_mean_diameters(ls_jammed.packing)
    path, failure = pivot_to_jamming(positions, diameters, box, singular[:, 0],
                                     singular[:, 1], ls_jammed.rattlers)
    assert path is None and failure == NEWTON_FAILED


def test_network_first_settles_a_singular_hint_with_its_near_pairs(ls_jammed, singular):
    """The hint's candidate holds its near pairs too; the restricted LP chooses the jammed
    network among them, with no LP, at the LP path's jamming point."""
    result = jam(ls_jammed.packing, network=singular, network_first="require")
    assert_jammed(result)
    assert result.stop_reason is StopReason.NETWORK_FIRST and result.iterations == 0
    assert result.packing.phi == pytest.approx(ls_jammed.packing.phi, rel=SAME_PHI)
    assert {tuple(p) for p in result.contacts} == {tuple(p) for p in ls_jammed.contacts}
