"""The extreme matrix, CI part: hard inputs end jammed with every invariant, or stop with an
error that names the problem.

Cases (numbers as in docs/stability.md): 1 nearly jammed input (LS at p = 1e12), 2 far from
jamming (φ0 ≈ 0.3 φ_J), 3 wide polydispersity, 4 the 2-d 50:50 mixture, 6 crystals,
7 round-off and real overlaps, 8 rectangular boxes, tiny N and a caged rattler. Case 9,
every backend on 1, 2 and 6, is in tests/test_backends.py; the larger instances (and case 5,
a small d = 5 box) are in tests/test_extremes_slow.py.
"""

from __future__ import annotations

import numpy as np
import pytest

import calippso
from calippso import Packing, jam
from calippso.geometry.neighbors import min_gap
from calippso.geometry.packing import ball_volume, minimum_image

import lattices
from configurations import (bidisperse, lognormal, overlap_free, phi_j,
                            random_sequential_addition)
from conftest import (BALANCE_TOLERANCE, OVERLAP_TOLERANCE, assert_jammed,
                      assert_rigid_and_balanced)

# ----------------------------------------------------------------------------- invariants

def assert_rigid(result) -> None:
    """Jammed, isostatic or hyperstatic (small or ordered packings can carry redundant
    contacts)."""
    assert_rigid_and_balanced(result)
    assert result.n_contacts > 0, result.status
    assert result.isostatic or result.isostaticity_gap > 0


def assert_crystal(result, lattice: str, caged: int = 0) -> None:
    """A jammed crystal: every lattice contact found, hyperstatic."""
    assert_rigid_and_balanced(result)
    packing = result.packing
    n_stable = packing.n - caged
    assert int(np.count_nonzero(result.rattlers)) == caged
    z = lattices.CONTACTS_PER_PARTICLE[lattice]
    expected = (z * packing.n) // 2 - z * caged
    assert result.n_contacts == expected
    gap = expected - packing.d * (n_stable - 1) - 1
    assert gap > 0 and result.isostaticity_gap == gap


# ----------------------------------------------------------------------------- inputs

def rsa_in_box(n: int, aspect, phi: float, seed: int, diameters=None) -> Packing:
    """Random sequential addition in a rectangular box of the given aspect (unit spheres
    unless `diameters` is given, shape (n,))."""
    aspect = np.asarray(aspect, dtype=float)
    d = aspect.shape[0]
    diameters = np.ones(n) if diameters is None else np.asarray(diameters, dtype=float)
    volume = float(np.sum(ball_volume(d, 0.5 * diameters))) / phi
    box = aspect * (volume / np.prod(aspect)) ** (1.0 / d)
    rng = np.random.default_rng(seed)
    placed = np.zeros((0, d))
    while placed.shape[0] < n:
        trial = rng.random(d) * box
        delta = minimum_image(placed - trial, box)
        sigma = 0.5 * (diameters[: placed.shape[0]] + diameters[placed.shape[0]])
        if np.all(np.einsum("nd,nd->n", delta, delta) > sigma**2):
            placed = np.vstack([placed, trial])
    return Packing(placed, diameters, box)


@pytest.fixture(scope="module")
def nearly_jammed_result(nearly_jammed):
    return jam(nearly_jammed)


# ----------------------------------------------------------------------------- 1. nearly jammed

def test_nearly_jammed_ls_input(nearly_jammed, nearly_jammed_result):
    result = nearly_jammed_result
    assert_jammed(result)
    # already at p = 1e12: few LPs, a small density change (measured: 3.4e-6 relative at
    # N = 128, more than the 1/p free-volume estimate: the LS state is not at its jamming point)
    assert result.iterations <= 30
    assert result.phi == pytest.approx(nearly_jammed.phi, rel=1e-5)
    assert result.phi >= nearly_jammed.phi


# ----------------------------------------------------------------------------- 2. far from jamming

@pytest.mark.parametrize("d, n", [(3, 64), (4, 64)])
def test_far_from_jamming(d, n):
    """φ0 = 0.3 φ_J: 30 to 60 LPs to a jammed packing near φ_J (larger N in
    tests/test_extremes_slow.py)."""
    start = random_sequential_addition(n, d, 0.3 * phi_j(d), seed=d)
    result = jam(start)
    assert_jammed(result)
    assert 0.9 * phi_j(d) < result.phi < 1.05 * phi_j(d)


# ----------------------------------------------------------------------------- 3. polydispersity

def test_wide_lognormal_polydispersity():
    sizes = lognormal(128, 0.3, seed=2)
    assert np.std(sizes) / np.mean(sizes) > 0.2
    start = random_sequential_addition(128, 3, 0.3, seed=2, diameters=sizes)
    result = jam(start)
    assert_jammed(result)
    ratio = result.packing.diameters / start.diameters   # one growth factor for every sphere
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-12)
    assert 0.62 < result.phi < 0.70


def test_one_to_five_bidisperse_mixture():
    start = random_sequential_addition(128, 3, 0.3, seed=3, diameters=bidisperse(128, 5.0))
    result = jam(start)
    assert_jammed(result)
    small = result.packing.diameters < result.packing.diameters.mean()
    # the small spheres fit in the holes of the large ones: most of them rattle
    assert result.rattlers[small].mean() > 0.5
    assert not result.rattlers[~small].all()


# ----------------------------------------------------------------------------- 4. 2-d mixture

def test_two_dimensional_50_50_mixture_ratio_1_4():
    start = random_sequential_addition(128, 2, 0.5, seed=4, diameters=bidisperse(128, 1.4))
    result = jam(start)
    assert_jammed(result)
    assert 0.82 < result.phi < 0.85


# ----------------------------------------------------------------------------- 6. crystals

@pytest.mark.parametrize("lattice, build", [
    ("fcc", lambda: lattices.fcc(3)), ("triangular", lambda: lattices.triangular(6)),
], ids=["fcc", "triangular"])
def test_jammed_crystal_at_contact_is_hyperstatic(lattice, build):
    start = build()
    result = jam(start)
    assert_crystal(result, lattice)
    assert result.phi == pytest.approx(start.phi, rel=1e-12)


@pytest.mark.parametrize("lattice, build", [
    ("fcc", lambda: lattices.fcc(3, fill=0.98)),
    ("triangular", lambda: lattices.triangular(6, fill=0.98)),
], ids=["fcc", "triangular"])
def test_loose_crystal_grows_back_to_contact(lattice, build):
    start = build()
    result = jam(start)
    assert_crystal(result, lattice)
    assert result.phi == pytest.approx(start.phi / 0.98 ** start.d, rel=1e-12)


def test_crystal_runs_end_without_overlap_or_error():
    """The unjammed lattices at contact (the others, at contact and loose, are jammed in the
    tests above): converged, no overlap, Σλσ² = 1, balanced forces, the lattice density (or
    a denser one) reached."""
    for start in (lattices.bcc(4), lattices.square(8)):
        result = jam(start)
        assert result.converged, result.status
        assert overlap_free(result.packing) >= -OVERLAP_TOLERANCE
        assert result.dual_normalization == pytest.approx(1.0, abs=1e-10)
        assert result.force_balance <= BALANCE_TOLERANCE
        assert result.phi >= start.phi * (1 - 1e-12)


def test_a_converged_run_that_nothing_holds_is_not_called_jammed(quenched_discs):
    """Monodisperse discs (N = 512, quench seed 2) crystallise in patches: the LPs meet the
    tolerances, but the network left is hypostatic or empty (every particle a rattler; which
    of the two depends on the LP solver's vertex among degenerate ones), so no rigid network
    holds the packing. The run says so (`StopReason.NOT_RIGID`, not converged), instead of
    claiming a jamming point; the packing itself is still free of overlaps."""
    result = jam(quenched_discs.packing, network=quenched_discs.contacts)
    assert result.stop_reason is calippso.StopReason.NOT_RIGID
    assert not result.converged and not result.isostatic
    assert result.n_stable == 0 or result.isostaticity_gap < 0
    assert result.status.startswith("Not jammed: the LPs converged after")
    assert overlap_free(result.packing) >= -OVERLAP_TOLERANCE


@pytest.fixture(scope="module")
def loose_unjammed_lattices() -> dict:
    """The square and BCC lattices at 98 % of contact, each jammed once for the module:
    name → (start, result)."""
    starts = {"square": lattices.square(8, 0.98), "bcc": lattices.bcc(4, 0.98)}
    return {name: (start, jam(start)) for name, start in starts.items()}


@pytest.mark.parametrize("name", ["square", "bcc"])
def test_unjammed_lattices_end_in_a_jammed_packing(name, loose_unjammed_lattices):
    """Square and BCC lattices are not jammed: the LP shears them into a denser packing."""
    start, result = loose_unjammed_lattices[name]
    assert_rigid(result)
    assert result.phi > start.phi / 0.98 ** start.d


def test_positive_self_stress_when_least_squares_is_not_positive(loose_unjammed_lattices):
    """The loose BCC lattice jams into a network whose self-stress nearest to uniform has a
    negative force; the contacts reported are all touching pairs, each carrying force."""
    from calippso.geometry.contacts import equilibrium_matrix, polish_forces, positive_self_stress

    result = loose_unjammed_lattices["bcc"][1]
    packing = result.packing
    i, j = result.contacts.T
    vectors = packing.positions[i] - packing.positions[j]
    vectors -= packing.box * np.round(vectors / packing.box)
    distances = np.linalg.norm(vectors, axis=1)
    normals = vectors / distances[:, None]
    weights = packing.diameters[i] ** 2 / distances
    assert polish_forces(packing.n, i, j, normals, weights, np.ones(len(i))).min() < 0
    forces = positive_self_stress(packing.n, i, j, normals, weights)
    assert forces.min() > 0 and weights @ forces == pytest.approx(1.0, rel=1e-12)
    assert np.abs(equilibrium_matrix(packing.n, i, j, normals) @ forces).max() < 1e-12 * forces.max()


def test_no_positive_self_stress_is_reported_as_none():
    """Two discs pushed the same way by both of their contacts cannot be in balance."""
    from calippso.geometry.contacts import positive_self_stress

    normals = np.array([[1.0, 0.0], [1.0, 0.0]])
    assert positive_self_stress(2, np.array([0, 0]), np.array([1, 1]), normals,
                                np.ones(2)) is None


# ----------------------------------------------------------------------------- 7. overlaps

def test_roundoff_overlaps_from_a_file_with_few_digits(tmp_path, nearly_jammed_result):
    jammed = nearly_jammed_result.packing
    path = tmp_path / "few_digits.dat"
    lines = ["3", f"{jammed.n} 1", str(jammed.n), "%.15g" % jammed.diameters[0],
             " ".join("%.15g" % v for v in np.diag(jammed.box).ravel()), "T T T"]
    lines += [" ".join("%.15g" % v for v in row) for row in jammed.positions]
    path.write_text("\n".join(lines) + "\n")
    start = calippso.read(path)
    gap, overlapping = min_gap(start.positions, start.diameters, start.box)
    assert overlapping > 0 and -1e-13 < gap < 0   # round-off overlaps, as files produce
    result = jam(start)
    assert_jammed(result)
    assert result.phi == pytest.approx(jammed.phi, rel=1e-12)


def test_roundoff_overlaps_of_1e14_on_every_contact(nearly_jammed_result):
    jammed = nearly_jammed_result.packing
    swollen = Packing(jammed.positions, jammed.diameters * (1 + 1e-14), jammed.box)
    assert min_gap(swollen.positions, swollen.diameters, swollen.box)[1] > 0
    assert_jammed(jam(swollen))


def test_real_overlap_is_refused_and_the_documented_repair_works(nearly_jammed):
    positions = nearly_jammed.positions.copy()
    delta = minimum_image(positions[1] - positions[0], nearly_jammed.box)
    positions[1] = positions[0] + delta / np.linalg.norm(delta) * (1 - 1e-3)
    overlapping = Packing(positions, nearly_jammed.diameters, nearly_jammed.box)
    with pytest.raises(ValueError, match=r"overlapping particles in the input: .* gap h = "):
        jam(overlapping)
    # the repair of docs/stability.md: shrink every diameter by the worst overlap
    gap, _ = min_gap(overlapping.positions, overlapping.diameters, overlapping.box)
    repaired = Packing(overlapping.positions, overlapping.diameters * (1 + gap) * (1 - 1e-12),
                       overlapping.box)
    assert min_gap(repaired.positions, repaired.diameters, repaired.box)[1] == 0
    assert_jammed(jam(repaired))


# ----------------------------------------------------------------------------- 8. boxes and sizes

@pytest.mark.parametrize("aspect", [(1.0, 2.0), (1.0, 1.5, 2.0)], ids=["2d-1x2", "3d-1x1.5x2"])
def test_rectangular_box(aspect):
    """Discs are the 50:50 mixture of ratio 1.4: equal discs order into a hyperstatic crystal
    or not depending on the solver's vertex choices (HiGHS 1.15 and 1.16 differ here)."""
    sizes = bidisperse(96, 1.4) if len(aspect) == 2 else None
    start = rsa_in_box(96, aspect, 0.3, seed=5, diameters=sizes)
    result = jam(start)
    assert_jammed(result)
    np.testing.assert_array_equal(result.packing.box, start.box)


@pytest.mark.parametrize("d, n, phi0, seed", [(2, 5, 0.4, 1), (2, 8, 0.4, 2), (2, 10, 0.4, 3),
                                              (3, 12, 0.2, 1)])
def test_tiny_systems(d, n, phi0, seed):
    """A few particles more than d + 1: jammed (5 discs form a square crystal: hyperstatic,
    reported as such), or an error that names the box."""
    start = random_sequential_addition(n, d, phi0, seed=seed)
    try:
        result = jam(start)
    except (ValueError, calippso.JammingError) as error:
        assert "box" in str(error) and "half" in str(error), error
        return
    assert_rigid(result)


@pytest.mark.parametrize("d, n", [(3, 1), (3, 2), (3, 6), (2, 4)])
def test_too_few_particles_to_jam_are_refused(d, n):
    """Fewer than 2 d + 1 particles cannot form an isostatic network under the minimum-image
    convention, whatever the box: a ValueError says so (not an IndexError, nor a box error)."""
    positions = np.random.default_rng(n).random((n, d)) * 5.0
    packing = Packing(positions, np.full(n, 0.5), np.full(d, 5.0))
    with pytest.raises(ValueError, match=rf"cannot jam {n} particle\(s\) in d = {d}: .* "
                                         rf"at least 2 d \+ 1 = {2 * d + 1} particles"):
        jam(packing)


def largest_hole(packing: Packing, samples: int, seed: int) -> tuple[np.ndarray, float]:
    """The sampled point farthest from every particle surface, and that clearance."""
    from scipy.spatial import cKDTree

    points = np.random.default_rng(seed).random((samples, packing.d)) * packing.box
    tree = cKDTree(packing.wrapped().positions, boxsize=packing.box)
    distances, neighbours = tree.query(points, k=8)
    clearance = (distances - 0.5 * packing.diameters[neighbours]).min(axis=1)
    best = int(np.argmax(clearance))
    return points[best], float(clearance[best])


def test_single_rattler_in_a_cage():
    """A small disc put into the largest hole of a jammed 2-d packing rattles there, and the
    packing around it stays as it was: the same network, rigid, already at its jamming point."""
    start = random_sequential_addition(64, 2, 0.5, seed=6, diameters=bidisperse(64, 1.4))
    jammed = jam(start)
    centre, clearance = largest_hole(jammed.packing, 20000, seed=1)
    assert clearance > 0.05
    caged = Packing(np.vstack([jammed.packing.positions, centre]),
                    np.append(jammed.packing.diameters, clearance), jammed.packing.box)
    result = jam(caged)
    assert_jammed(result)
    assert result.rattlers[-1]
    assert result.n_contacts == jammed.n_contacts
    np.testing.assert_array_equal(result.rattlers[:-1], jammed.rattlers)
    np.testing.assert_allclose(result.packing.diameters[:-1], jammed.packing.diameters,
                               rtol=1e-9)


def test_single_rattler_in_a_crystal_cage():
    start = lattices.triangular(6)
    diameters = start.diameters.copy()
    diameters[7] = 0.5
    result = jam(Packing(start.positions, diameters, start.box))
    assert_crystal(result, "triangular", caged=1)
    assert result.rattlers[7]
