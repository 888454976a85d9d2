"""A run that ends on the LP tolerances says "Jammed" only if its network is rigid.

`calippso.stages.finish` runs the linear test of collective jamming (`calippso.categories`)
on the final network and every other touching pair of a `CONVERGED` run; an unjamming
motion makes the run `NOT_RIGID`, with a note that says so.
"""

from __future__ import annotations

import numpy as np

from calippso.geometry.neighbors import NeighborSearch
from calippso.stages.finish import _unjamming_motion
from calippso.geometry.touching import touching_outside_network

import lattices


def _touching(packing):
    search = NeighborSearch(packing.positions, packing.diameters, packing.box)
    close = search.pairs_near_contact()
    close = close.subset(np.abs(close.gaps) < 1e-12)
    return np.column_stack([close.i, close.j]).astype(np.int64)


def _check(packing, contacts):
    """`_unjamming_motion` on a periodic packing without rattlers."""
    no_walls = np.zeros((0, 2), np.int64)
    rattlers = np.zeros(packing.n, dtype=bool)
    touching = touching_outside_network(packing, contacts, rattlers, no_walls)
    return _unjamming_motion(packing, contacts, no_walls, rattlers, touching)


def test_sliding_rows_are_an_unjamming_motion():
    """The square lattice of discs at contact counts 2N contacts, one more than isostatic,
    yet its rows slide (Torquato & Stillinger, Rev. Mod. Phys. 82, 2633 (2010), Table I)."""
    square = lattices.square(8)
    contacts = _touching(square)
    assert len(contacts) == 2 * square.n               # hyperstatic by count
    why, undecided = _check(square, contacts)
    assert undecided is None
    assert why is not None and "not rigid" in why


def test_a_jammed_lattice_passes():
    triangular = lattices.triangular(6)
    why, undecided = _check(triangular, _touching(triangular))
    assert why is None and undecided is None


def test_touching_pairs_outside_the_network_count_as_constraints():
    """Given only half the triangular lattice's contacts, the test still finds it rigid:
    the pairs that touch outside the network hold it too."""
    triangular = lattices.triangular(6)
    contacts = _touching(triangular)
    why, _ = _check(triangular, contacts[::2])
    assert why is None
