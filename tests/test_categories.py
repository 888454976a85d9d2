"""Jamming categories (`calippso.jamming_category`): textbook lattices, a jammed result, the
witnesses checked against an independent computation of the linearised constraints."""

from __future__ import annotations

import numpy as np
import pytest

import lattices
from calippso import Boundaries, Packing, jam, jamming_category
from calippso.categories import DEFAULT_CONTACT_TOLERANCE

#: A witness closes no contact faster than this (relative to its largest component).
CLOSING_TOLERANCE = 1e-8
#: Forces of a certificate balance on every particle to this (mean force 1).
BALANCE_TOLERANCE = 1e-10


def _separations(packing: Packing, pairs: np.ndarray) -> np.ndarray:
    """Minimum-image vectors from i to j of every pair, by the plain formula, shape (M, d)."""
    delta = packing.positions[pairs[:, 1]] - packing.positions[pairs[:, 0]]
    sides = np.where(packing.periodic, packing.box, np.inf)
    return delta - np.where(packing.periodic, packing.box, 0.0) * np.round(delta / sides)


def assert_unjamming(packing: Packing, category) -> None:
    """The witness is a nontrivial motion that closes no contact to first order and does not
    grow the box: n_ijᵀ (Δr_j − Δr_i + ε r_ij) ≥ 0 for every contact, tr ε ≤ 0."""
    motion = category.displacements
    strain = np.zeros((packing.d, packing.d)) if category.strain is None else category.strain
    assert motion.shape == (packing.n, packing.d)
    assert np.allclose(strain, strain.T)
    assert np.all(motion[category.rattlers] == 0)
    u = _separations(packing, category.contacts)
    normals = u / np.linalg.norm(u, axis=1)[:, None]
    relative = motion[category.contacts[:, 1]] - motion[category.contacts[:, 0]] + u @ strain.T
    rates = np.einsum("md,md->m", normals, relative)
    size = max(np.abs(motion).max(), np.abs(strain).max())
    assert rates.min() >= -CLOSING_TOLERANCE * size
    assert np.trace(strain) <= CLOSING_TOLERANCE * size
    if category.failed == "local":   # one particle moves, the others stay
        assert np.count_nonzero(np.abs(motion).max(axis=1)) == 1
    else:                            # not a translation
        stable = ~category.rattlers
        moving = motion[stable] - motion[stable].mean(axis=0)
        assert max(np.abs(moving).max(), np.abs(strain).max()) > 0.1
    if category.opens_contacts:
        assert rates.max() > 1e-6 * size


def assert_certified(packing: Packing, category) -> None:
    """The certificate: positive forces in balance on every stable particle; for a strictly
    jammed packing their stress Σ f r ⊗ n / V is isotropic, at the reported pressure."""
    forces = category.forces
    assert forces is not None and forces.min() > 0
    u = _separations(packing, category.contacts)
    normals = u / np.linalg.norm(u, axis=1)[:, None]
    net = np.zeros((packing.n, packing.d))
    np.add.at(net, category.contacts[:, 0], -forces[:, None] * normals)
    np.add.at(net, category.contacts[:, 1], forces[:, None] * normals)
    assert np.abs(net).max() < BALANCE_TOLERANCE
    if category.category == "strict":
        stress = np.einsum("m,ma,mb->ab", forces, u, normals) / packing.volume
        assert category.pressure > 0
        assert np.allclose(stress, category.pressure * np.eye(packing.d), atol=1e-10)


# ----------------------------------------------------------------------------- lattices
@pytest.mark.parametrize("packing", [lattices.triangular(4), lattices.fcc(2),
                                     lattices.checkerboard(4, 2)],
                         ids=["triangular", "fcc", "d4"])
def test_close_packed_lattices_are_strictly_jammed(packing):
    category = jamming_category(packing)
    assert category.category == "strict"
    assert category.failed is None and category.displacements is None
    assert not category.rattlers.any()
    assert_certified(packing, category)


@pytest.mark.parametrize("packing", [lattices.honeycomb(3), lattices.square(4),
                                     lattices.simple_cubic(3), lattices.bcc(3)],
                         ids=["honeycomb", "square", "simple-cubic", "bcc"])
def test_open_lattices_are_locally_but_not_collectively_jammed(packing):
    # Torquato & Stillinger, Rev. Mod. Phys. 82, 2633 (2010), Table I: locally jammed, not
    # collectively jammed in a periodic box (rows slide, the honeycomb shears).
    category = jamming_category(packing)
    assert category.category == "local"
    assert category.failed == "collective"
    assert_unjamming(packing, category)


def test_periodic_kagome_twists_open():
    # In a periodic box the kagome is only locally jammed: its triangles twist, a motion
    # that keeps every contact closed to first order in the fixed box (the strain-free
    # twist of the twisted kagome lattice, Sun, Souslov, Mao & Lubensky, PNAS 109, 12369
    # (2012)). Lists of jammed lattices call it collectively but not strictly jammed
    # (Torquato & Stillinger, J. Phys. Chem. B 105, 11849 (2001)); not in a periodic box.
    # The first-order motion is a real one: moving along it by t changes every contact
    # distance by t²|Δr_j − Δr_i|²/(2|r_ij|) ≥ 0, checked here on every pair.
    packing = lattices.kagome(2)
    category = jamming_category(packing)
    assert category.category == "local"
    assert not category.opens_contacts
    assert_unjamming(packing, category)
    moved = Packing(packing.positions + 1e-3 * category.displacements, packing.diameters,
                    packing.box)
    every = np.array([(i, j) for i in range(packing.n) for j in range(i + 1, packing.n)])
    before = np.linalg.norm(_separations(packing, every), axis=1)
    after = np.linalg.norm(_separations(moved, every), axis=1)
    assert after.min() >= 1.0 - 1e-12
    assert (after - before)[before < 1 + 1e-9].max() > 1e-8


def test_a_disc_held_from_one_side_is_not_jammed():
    # the three neighbours on the right of disc 0 removed: its three other contacts keep it
    # out of the rattlers, but all push from the left, and it moves alone to the right
    crystal = lattices.triangular(4)
    u = _separations(crystal, np.stack([np.zeros(crystal.n, int), np.arange(crystal.n)], 1))
    right = (np.linalg.norm(u, axis=1) < 1 + 1e-9) & (u[:, 0] > 0.1)
    assert right.sum() == 3
    packing = Packing(crystal.positions[~right], crystal.diameters[~right], crystal.box)
    category = jamming_category(packing)
    assert category.category == "not jammed" and category.failed == "local"
    assert not category.rattlers.any()
    assert category.opens_contacts
    assert_unjamming(packing, category)
    assert category.displacements[0, 0] > 0 and np.abs(category.displacements[1:]).max() == 0


def test_a_packing_without_contacts_is_not_jammed():
    packing = lattices.square(4, fill=0.9)
    category = jamming_category(packing)
    assert category.category == "not jammed" and category.rattlers.all()
    assert len(category.contacts) == 0
    assert np.count_nonzero(np.abs(category.displacements).max(axis=1)) == 1


def test_a_rattler_removed_and_put_back_changes_nothing():
    crystal = lattices.fcc(2)
    keep = np.arange(crystal.n) != 5
    vacancy = Packing(crystal.positions[keep], crystal.diameters[keep], crystal.box)
    diameters = crystal.diameters.copy()
    diameters[5] = 0.6                 # a small sphere rattling in the vacancy
    rattling = Packing(crystal.positions, diameters, crystal.box)
    without, back = jamming_category(vacancy), jamming_category(rattling)
    assert back.rattlers.sum() == 1 and back.rattlers[5]
    assert without.category == back.category
    renumber = np.flatnonzero(keep)
    assert np.array_equal(renumber[without.contacts], back.contacts)
    assert np.allclose(without.forces, back.forces)


# ----------------------------------------------------------------------------- jammed results
@pytest.fixture(scope="module")
def jammed_128(nearly_jammed):
    """`calippso.jam` of the N = 128, d = 3 LS packing at p = 1e12."""
    return jam(nearly_jammed)


def test_a_jammed_result_is_collectively_jammed(jammed_128):
    category = jamming_category(jammed_128)
    # isostatic: by counting it lacks d(d+1)/2 − 1 contacts for strict jamming
    assert jammed_128.isostatic
    assert category.category == "collective"
    assert category.contact_tolerance is None
    assert np.array_equal(category.contacts, jammed_128.contacts)
    assert np.array_equal(category.rattlers, jammed_128.rattlers)
    assert_certified(jammed_128.packing, category)
    assert_unjamming(jammed_128.packing, category)      # a strain that the network allows
    assert category.strain is not None and np.abs(category.strain).max() > 0


def test_the_bare_packing_of_a_result_finds_the_same_contacts(jammed_128):
    from_result = jamming_category(jammed_128)
    from_gaps = jamming_category(jammed_128.packing)
    assert from_gaps.contact_tolerance == DEFAULT_CONTACT_TOLERANCE
    assert np.array_equal(from_gaps.contacts, from_result.contacts)
    assert from_gaps.category == from_result.category


@pytest.fixture(scope="module")
def jammed_discs():
    """`calippso.jam` of a soft quench of 64 discs, a 1:1.4 bidisperse mixture (2 rattlers)."""
    import generators

    quench = generators.soft_quench(generators.diameters.bidisperse(64, 1.4), 2, seed=2)
    return jam(quench.packing, network=quench.contacts)


def test_jammed_discs_are_collectively_but_not_strictly_jammed(jammed_discs):
    category = jamming_category(jammed_discs)
    assert category.category == "collective"
    assert_certified(jammed_discs.packing, category)
    assert_unjamming(jammed_discs.packing, category)


def test_rattlers_cleared_from_their_cages_do_not_make_gaps_ambiguous(jammed_discs):
    # `jam` leaves its rattlers ~1e-9 from their cages, inside the ambiguity window of the
    # default tolerance; they are rattlers either way, so the bare packing is accepted
    from_gaps = jamming_category(jammed_discs.packing)
    assert np.array_equal(from_gaps.rattlers, jammed_discs.rattlers)
    assert np.array_equal(from_gaps.contacts, jammed_discs.contacts)
    assert from_gaps.category == "collective"


def test_removing_a_rattler_of_a_result_changes_nothing(jammed_discs):
    packing = jammed_discs.packing
    rattlers = np.flatnonzero(jammed_discs.rattlers)
    assert rattlers.size
    keep = np.arange(packing.n) != rattlers[0]
    fewer = Packing(packing.positions[keep], packing.diameters[keep], packing.box)
    with_it, without = jamming_category(packing), jamming_category(fewer)
    assert with_it.category == without.category == "collective"
    assert np.array_equal(np.flatnonzero(keep)[without.contacts], with_it.contacts)


# ----------------------------------------------------------------------------- containers
def _triangular_slab(columns: int, rows: int) -> Packing:
    """Rows of touching discs along x (periodic), stacked as the triangular lattice between
    flat walls in y that touch the first and last rows."""
    height = np.sqrt(3.0) / 2
    positions = np.array([((k + 0.5 * (row % 2)) % columns, 0.5 + row * height)
                          for row in range(rows) for k in range(columns)])
    box = np.array([float(columns), 1.0 + (rows - 1) * height])
    return Packing(positions, np.ones(len(positions)), box, Boundaries.walls(2, "y"))


def test_walls_stay_and_the_periodic_axis_strains():
    slab = _triangular_slab(6, 4)
    category = jamming_category(slab)
    assert len(category.wall_contacts) == 12
    assert category.category == "strict"
    assert category.wall_forces.min() > 0


def _fcc_slab(cells: int) -> Packing:
    """FCC of unit spheres with its (100) layers between flat walls in x that touch the
    first and last layers, periodic in y and z."""
    half = np.sqrt(2.0) / 2    # half the cubic cell
    sites = [(0.5 + i * half, j * half, k * half) for i in range(2 * cells)
             for j in range(2 * cells) for k in range(2 * cells) if (i + j + k) % 2 == 0]
    box = np.array([1.0 + (2 * cells - 1) * half, 2 * cells * half, 2 * cells * half])
    return Packing(np.array(sites), np.ones(len(sites)), box, Boundaries.walls(3, "x"))


def test_a_hyperstatic_slab_with_two_periodic_axes_is_decided_by_the_lps():
    """The strict LPs in a container: the stress of the certificate is isotropic on the
    periodic axes y, z (the walls take the load along x)."""
    slab = _fcc_slab(2)
    category = jamming_category(slab)
    assert category.category == "strict" and category.tests[-1].method == "linear programs"
    assert category.forces.min() > 0 and category.wall_forces.min() > 0
    assert category.balance < BALANCE_TOLERANCE
    u = _separations(slab, category.contacts)
    normals = u / np.linalg.norm(u, axis=1)[:, None]
    stress = np.einsum("m,ma,mb->ab", category.forces, u, normals)[1:, 1:] / slab.volume
    np.testing.assert_allclose(stress, category.pressure * np.eye(2), atol=1e-10)


def test_one_periodic_axis_is_decided_by_any_positive_self_stress():
    """The slab is hyperstatic (many self-stresses): with x the only periodic axis, the
    collective certificate with the volume force g = σ_xx V proves strict jamming."""
    slab = _triangular_slab(6, 4)
    category = jamming_category(slab)
    assert [test.method for test in category.tests] == ["linear programs", "self-stress",
                                                        "strain"]
    assert category.forces.min() > 0 and category.balance < BALANCE_TOLERANCE
    u = _separations(slab, category.contacts)
    normals = u / np.linalg.norm(u, axis=1)[:, None]
    stress_xx = float(np.sum(category.forces * u[:, 0] * normals[:, 0])) / slab.volume
    assert category.pressure == pytest.approx(stress_xx, rel=1e-12)


def test_an_lp_that_highs_fails_is_solved_again_or_refused_in_one_line(monkeypatch):
    """The strict test's cone LP by the next method when one fails (an iteration limit of 0
    here; HiGHS can end a degenerate cone with an unknown status); SolverError when all
    fail."""
    from calippso import categories
    from calippso.errors import SolverError

    crystal = lattices.fcc(2)
    failing = ("highs-ds", {"maxiter": 0})
    monkeypatch.setattr(categories, "LP_ATTEMPTS", (failing, *categories.LP_ATTEMPTS))
    assert jamming_category(crystal).category == "strict"
    monkeypatch.setattr(categories, "LP_ATTEMPTS", (failing,))
    with pytest.raises(SolverError, match="the jamming test's LP failed") as refused:
        jamming_category(crystal)
    assert "\n" not in str(refused.value)


def test_a_container_without_periodic_axis_is_refused_for_the_strict_test():
    slab = _triangular_slab(6, 4)
    closed = Packing(slab.positions + [0.5, 0.0], slab.diameters, slab.box + [1.0, 0.0],
                     Boundaries.walls(2, ("x", "y")))
    with pytest.raises(ValueError, match="periodic axis"):
        jamming_category(closed)
    tested = jamming_category(closed, up_to="collective").tests
    assert "strict" not in [test.name for test in tested]


# ----------------------------------------------------------------------------- bad input
def test_ambiguous_gaps_are_refused_and_a_chosen_tolerance_is_reported():
    packing = lattices.triangular(4, fill=1 - 1e-8)    # every contact open by ~1e-8
    with pytest.raises(ValueError, match="ambiguous"):
        jamming_category(packing)
    category = jamming_category(packing, contact_tolerance=1e-7)
    assert category.contact_tolerance == 1e-7
    assert category.category == "strict"


def test_overlaps_and_other_inputs_are_refused():
    packing = lattices.square(4)
    grown = Packing(packing.positions, packing.diameters * (1 + 1e-6), packing.box)
    with pytest.raises(ValueError, match="overlaps"):
        jamming_category(grown)
    with pytest.raises(ValueError, match="Packing or a JammingResult"):
        jamming_category(packing.positions)
    with pytest.raises(ValueError, match="contact_tolerance"):
        jamming_category(packing, contact_tolerance=-1.0)
    with pytest.raises(ValueError, match="up_to"):
        jamming_category(packing, up_to="everything")
