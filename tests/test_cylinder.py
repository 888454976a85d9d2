"""A cylinder container in `jam`: the safe LP row of a curved wall, the Newton stage with the
rotation held, and jammed packings checked with the physics (no overlap, inside the circle,
isostatic with two zero modes, force balance with the wall's forces, the virial)."""

from __future__ import annotations

import numpy as np
import pytest

import calippso
from calippso import Boundaries, Packing
from calippso.certification.newton import refine_isostatic
from calippso.geometry.walls import CIRCLE_AXES, cylinder_wall, wall_rows_of

from configurations import lognormal, random_sequential_addition

#: Largest net force on a particle, relative to the mean force.
BALANCE = 1e-12
#: Largest overlap of two particles or of a particle and the cylinder (relative gap).
OVERLAP = 1e-14
#: A contact's relative gap is at most this.
CONTACT_GAP = 1e-9


def cylinder_start(n: int, d: int, seed: int, polydisperse: bool) -> Packing:
    """A random non-overlapping start inside a cylinder in the plane of axes x, y."""
    sizes = lognormal(n, 0.1, seed) if polydisperse else None
    phi = 0.45 if d == 2 else 0.3
    return random_sequential_addition(n, d, phi, seed, sizes, Boundaries.cylinder(d, (0, 1)))


def test_the_cylinder_row_is_safe_over_any_step_within_the_bound():
    """Over every step with components at most b, the distance of a particle to the cylinder
    is at least δ' + e_w·s with δ' = δ − b²/ρ (`WallRows.row_distances`): the LP row built on
    δ' never lets a particle cross the wall, although the wall curves towards it."""
    rng = np.random.default_rng(7)
    box = np.array([6.0, 6.0, 4.0])
    radius = 0.5 * box[0]
    n = 4000
    angle = rng.uniform(0, 2 * np.pi, n)
    rho = radius - rng.uniform(0.3, 0.7, n)                 # near the wall
    positions = np.column_stack([3.0 + rho * np.cos(angle), 3.0 + rho * np.sin(angle),
                                 rng.uniform(0, 4, n)])
    rows = wall_rows_of(positions, np.ones(n), box, np.arange(n),
                        np.full(n, cylinder_wall(3)), (0, 1))
    for bound in (0.01, 0.1, 0.3):
        # the worst steps are tangential, at the corners of the box of bounds
        steps = rng.choice([-bound, bound], size=(n, 3)) * rng.uniform(0.5, 1.0, (n, 1))
        after = positions + steps
        exact = radius - np.linalg.norm(after[:, :2] - 3.0, axis=1)
        predicted = rows.row_distances(bound) + np.einsum("nd,nd->n", rows.normals, steps)
        assert np.all(exact >= predicted - 1e-15)
        # the margin is the whole second-order term of a corner step: no more than needed
        assert np.min(exact - predicted) <= 0.5 * CIRCLE_AXES * bound**2 / rho.min()


def assert_jammed_in_a_cylinder(result) -> None:
    packing = result.packing
    d, boundaries = packing.d, packing.boundaries
    a, b = boundaries.cylinder_axes
    radius = 0.5 * packing.box[a]
    centre = 0.5 * packing.box[[a, b]]
    offset = packing.positions[:, [a, b]] - centre
    rho = np.linalg.norm(offset, axis=1)
    # inside the circle, no pair overlaps (minimum image along the periodic axes only)
    assert np.min((radius - rho) / (packing.diameters / 2) - 1) >= -OVERLAP
    delta = packing.positions[:, None, :] - packing.positions[None, :, :]
    periodic = boundaries.periodic
    delta -= np.where(periodic, packing.box, 0.0) * np.round(delta / packing.box)
    sigma = 0.5 * (packing.diameters[:, None] + packing.diameters[None, :])
    h = np.linalg.norm(delta, axis=2) / sigma - 1
    np.fill_diagonal(h, np.inf)
    assert h.min() >= -OVERLAP
    # contacts touch; wall contacts are with the cylinder and touch it
    i, j = result.contacts.T
    vectors = delta[i, j]
    distances = np.linalg.norm(vectors, axis=1)
    assert np.abs(distances / sigma[i, j] - 1).max() < CONTACT_GAP
    particle, wall = result.wall_contacts.T
    assert result.n_wall_contacts > 0 and np.all(wall == cylinder_wall(d))
    assert np.abs((radius - rho[particle]) / (packing.diameters[particle] / 2) - 1).max() \
        < CONTACT_GAP
    assert np.all(result.forces > 0) and np.all(result.wall_forces > 0)
    # every stable particle in balance, the cylinder pushing towards its axis
    inward = np.zeros((particle.size, d))
    inward[:, [a, b]] = -offset[particle] / rho[particle, None]
    net = np.zeros((packing.n, d))
    normals = vectors / distances[:, None]
    np.add.at(net, i, result.forces[:, None] * normals)
    np.add.at(net, j, -result.forces[:, None] * normals)
    np.add.at(net, particle, result.wall_forces[:, None] * inward)
    assert np.abs(net).max() <= BALANCE
    assert result.force_balance <= BALANCE
    # isostatic: N_c = d N_s + 1 - (periodic translations + the rotation about the axis)
    n_stable = int(np.count_nonzero(~result.rattlers))
    assert result.n_contacts == d * n_stable + 1 - (boundaries.n_periodic + 1), result.status
    assert result.isostatic
    # virial in the plane of the circle: Σ_pairs f |r_⊥|²/|r| = Σ_walls f (R − σ_i/2), and
    # the cylinder's pressure is its load over its area
    pairs = np.sum(result.forces * np.sum(vectors[:, [a, b]] ** 2, axis=1) / distances)
    walls = np.sum(result.wall_forces * (radius - packing.diameters[particle] / 2))
    assert pairs == pytest.approx(walls, rel=1e-10)
    area = np.pi * packing.box[a] * np.prod(packing.box[periodic])
    assert result.cylinder_pressure == pytest.approx(result.wall_forces.sum() / area,
                                                     rel=1e-12)


@pytest.mark.parametrize("d, n, seed, polydisperse", [
    (2, 96, 1, True),
    # d = 3 in the fast suite: test_packing_generation_cylinder_is_read_jammed_and_verified
    pytest.param(3, 128, 2, True, marks=pytest.mark.slow),
    pytest.param(3, 128, 1, False, marks=pytest.mark.slow),
])
def test_jam_in_a_cylinder(d, n, seed, polydisperse):
    start = cylinder_start(n, d, seed, polydisperse)
    result = calippso.jam(start)
    assert result.converged, result.status
    assert result.packing.boundaries == start.boundaries
    assert_jammed_in_a_cylinder(result)


def test_newton_in_a_cylinder_returns_to_the_jamming_point():
    """From a jammed cylinder packing moved by 1e-6, the Newton stage (one coordinate holds the
    rotation about the axis) comes back to the same φ_J with positive forces."""
    result = calippso.jam(cylinder_start(96, 2, 1, True))
    packing = result.packing
    stable = ~result.rattlers
    rng = np.random.default_rng(4)
    moved = packing.positions + 1e-6 * rng.standard_normal(packing.positions.shape) * stable[:,
                                                                                             None]
    i, j = result.contacts.T
    particle, wall = result.wall_contacts.T
    refined = refine_isostatic(moved, packing.diameters, packing.box, i, j, stable,
                               wall_particle=particle, wall=wall,
                               boundaries=packing.boundaries)
    assert refined is not None and refined.positive
    phi = packing.phi * (1 + refined.sqrt_gamma_minus_1) ** packing.d
    assert phi == pytest.approx(packing.phi, abs=1e-9)
    every = np.concatenate([refined.forces, refined.wall_forces])
    np.testing.assert_allclose(every / every.mean(),
                               np.concatenate([result.forces, result.wall_forces]), rtol=1e-6)


def test_packing_generation_cylinder_is_read_jammed_and_verified(tmp_path):
    """PackingGeneration's cylinder mode (2): a circle of diameter X = Y in xy, centred in the
    box, periodic in z. A folder written in its format is read as that cylinder, with the
    diameters rescaled by the porosities of its .nfo, and jams."""
    start = random_sequential_addition(96, 3, 0.3, 6, lognormal(96, 0.1, 6),
                                       Boundaries.cylinder(3, (0, 1)))
    theoretical, final = 0.45, 1.0 - start.phi
    scale = ((1.0 - final) / (1.0 - theoretical)) ** (1.0 / 3.0)
    folder = tmp_path / "cylinder"
    folder.mkdir()
    np.column_stack([start.positions, start.diameters / scale]).astype("<f8").tofile(
        folder / "packing.xyzd")
    (folder / "packing.nfo").write_text(
        f"N: {start.n}\n Theoretical Porosity: {theoretical:.17g}\n"
        f"Final Porosity: {final:.17g} (Tolerance: 1.000100)\n")
    (folder / "generation.conf").write_text(
        f"Particles count: {start.n}\nPacking size: {' '.join(f'{v:.17g}' for v in start.box)}"
        f"\nGeneration start: 0\nSeed: 6\nSteps to write: 1000\nBoundaries mode: 2\n"
        f"Contraction rate: 0.01\nGeneration mode: 1\n")
    packing = calippso.read(folder)
    assert packing.boundaries == Boundaries.cylinder(3, (0, 1))
    np.testing.assert_allclose(packing.diameters, start.diameters, rtol=1e-14)
    result = calippso.jam(packing)
    assert_jammed_in_a_cylinder(result)
    written = calippso.write(result.packing, tmp_path / "again" / "packing.xyzd")
    assert "Boundaries mode: 2" in (written.parent / "generation.conf").read_text()
    again = calippso.read(written.parent)
    assert again.boundaries == packing.boundaries
    np.testing.assert_allclose(again.positions, result.packing.positions, rtol=0, atol=1e-13)
