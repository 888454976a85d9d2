"""`jam(box="deformable")` in containers: flat walls on some axes or a cylinder, the strain
on the periodic axes only.

Each container (walls in x in d = 2 and 3, walls in x and y in d = 3, a cylinder in x, y in
d = 3) is jammed from a loose start (random sequential addition) twice: in the fixed box, and
then in the deformable box from the fixed box's jamming point. The deformable run from there
can only gain density (every LP has the zero step, and a traceless strain shrinks the volume
at second order), and it ends strictly jammed: no overlap (walls included), the strict count
N_c = d N_s − (zero modes) + d_p(d_p+1)/2 (d_p periodic axes), positive forces in balance,
an isotropic stress on the periodic axes, walls where they were. The deformable run from the
loose start itself reaches another jamming point (the LPs' trajectory picks it, denser or
not than the fixed box's), certified the same way. Then the checkpoint and SIGKILL resume in
a container, and the refusal of a container without a periodic axis.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from configurations import bidisperse, container_gaps, random_sequential_addition
from conftest import kill_after_saved_lps

from calippso import Boundaries, StopReason, jam, jamming_category
from calippso.deformable import strain_count, strict_zero_modes
from calippso.io import read_result, write

#: The containers, by name: (d, boundaries, N, φ of the loose start).
CONTAINERS = {
    "walls x, d=2": (2, Boundaries.walls(2, ["x"]), 128, 0.5),
    "walls x, d=3": (3, Boundaries.walls(3, ["x"]), 96, 0.3),
    "walls x, y, d=3": (3, Boundaries.walls(3, ["x", "y"]), 96, 0.3),
    "cylinder x, y, d=3": (3, Boundaries.cylinder(3, ["x", "y"]), 96, 0.3),
}
#: Seed of the loose starts.
SEED = 1
#: Overlaps and crossings of a wall allowed, relative to the contact distance.
OVERLAP = 1e-12
#: Largest net force on a stable particle (forces of mean 1).
BALANCE = 1e-12
#: Largest anisotropy of the stress on the periodic axes, max |σ − p I| / p.
ISOTROPY = 1e-12
#: φ may fall below the fixed box's by this relative amount: the diameters shrunk by the
#: final round-off overlaps, and in a cylinder the margin b²/ρ of its safe rows at the
#: smallest step bound (the last LP's γ can be −1e-10 there).
PHI_ROUNDOFF = 1e-9
#: The LPs after which the checkpoint test's run is killed.
KILLED_AFTER = 8


def killed_start():
    """The checkpoint test's loose start: 64 spheres between walls in x (d = 3)."""
    return random_sequential_addition(64, 3, 0.3, seed=2,
                                      boundaries=Boundaries.walls(3, ["x"]))


def loose_start(name: str):
    d, boundaries, n, phi = CONTAINERS[name]
    return random_sequential_addition(n, d, phi, seed=SEED, boundaries=boundaries,
                                      diameters=bidisperse(n) if d == 2 else None)


@pytest.fixture(scope="module", params=list(CONTAINERS))
def runs(request):
    """(name, loose start, fixed-box result, deformable run from the fixed box's jamming
    point, deformable run from the loose start)."""
    start = loose_start(request.param)
    fixed = jam(start)
    assert fixed.converged, fixed.status
    return (request.param, start, fixed, jam(fixed.packing, box="deformable"),
            jam(start, box="deformable"))


def minimum_images(packing) -> np.ndarray:
    """Every pair's separation at its nearest image through the periodic box vectors alone
    (brute force over the 3^{d_p} neighbouring cells), shape (N (N − 1)/2, d)."""
    i, j = np.triu_indices(packing.n, 1)
    delta = packing.positions[i] - packing.positions[j]
    vectors = packing.lattice[:, packing.periodic]
    best = delta.copy()
    for shift in itertools.product((-2, -1, 0, 1, 2), repeat=vectors.shape[1]):
        moved = delta + vectors @ np.array(shift, dtype=float)
        closer = np.linalg.norm(moved, axis=1) < np.linalg.norm(best, axis=1)
        best[closer] = moved[closer]
    return best


def assert_strictly_jammed_in(result, start) -> None:
    """Strictly jammed in the container of `start`, with every certificate checked here."""
    packing, boundaries = result.packing, start.boundaries
    assert result.converged and result.category == "strict", result.status
    assert result.box_mode == "deformable" and packing.boundaries == boundaries
    # the walls stay: their axes keep their sides and no shear touches them
    bounded = ~boundaries.periodic
    np.testing.assert_allclose(packing.box[bounded], start.box[bounded], rtol=1e-13)
    lattice = packing.lattice
    off = ~np.eye(packing.d, dtype=bool) & (bounded[:, None] | bounded[None, :])
    assert np.all(lattice[off] == 0.0)
    # no overlap, with the particles and with the walls
    i, j = np.triu_indices(packing.n, 1)
    sigma = 0.5 * (packing.diameters[i] + packing.diameters[j])
    assert np.min(np.linalg.norm(minimum_images(packing), axis=1) / sigma - 1) >= -OVERLAP
    assert container_gaps(packing)[1].min() >= -OVERLAP
    # the strict count: the container's rigid motions less the periodic axes' shape
    d_p = int(boundaries.periodic.sum())
    expected = packing.d * result.n_stable - boundaries.zero_modes + strain_count(d_p)
    assert result.n_contacts == expected and result.isostatic
    assert result.n_wall_contacts > 0
    # positive forces in balance, an isotropic stress on the periodic axes
    assert result.forces.min() > 0 and result.wall_forces.min() > 0
    assert result.force_balance <= BALANCE
    assert result.pressure > 0 and result.stress_anisotropy <= ISOTROPY


def test_the_strict_count_adds_the_periodic_axes_shape():
    for d, boundaries in ((2, Boundaries.walls(2, ["x"])), (3, Boundaries.walls(3, ["x"])),
                          (3, Boundaries.walls(3, ["x", "y"])),
                          (3, Boundaries.cylinder(3, ["x", "y"]))):
        d_p = int(boundaries.periodic.sum())
        shape_at_fixed_volume = d_p * (d_p + 1) // 2 - 1
        assert strict_zero_modes(boundaries) == boundaries.zero_modes - shape_at_fixed_volume


def test_from_the_fixed_box_jamming_point_it_ends_strictly_jammed_and_no_looser(runs):
    name, start, fixed, from_fixed, _ = runs
    assert_strictly_jammed_in(from_fixed, start)
    assert from_fixed.phi >= fixed.phi * (1.0 - PHI_ROUNDOFF), name


def test_from_the_loose_start_it_ends_strictly_jammed(runs):
    _, start, _, _, from_loose = runs
    assert_strictly_jammed_in(from_loose, start)
    assert from_loose.stop_reason in (StopReason.CERTIFIED_NEWTON, StopReason.CONVERGED)


def test_the_linear_test_finds_the_result_strictly_jammed(runs):
    """`calippso.jamming_category` (the strict test on the periodic axes) on the run's own
    contacts agrees with the run's certificate."""
    _, _, _, from_fixed, from_loose = runs
    for result in (from_fixed, from_loose):
        assert jamming_category(result).category == "strict"


def test_run_killed_by_sigkill_in_a_container_resumes(tmp_path):
    start = killed_start()
    uninterrupted = jam(start, box="deformable")
    assert uninterrupted.iterations > KILLED_AFTER + 1
    path = tmp_path / "killed.npz"
    script = ("from test_deformable_containers import killed_start\n"
              "from calippso import jam\n"
              f"jam(killed_start(), box='deformable', checkpoint={str(path)!r})\n")
    kill_after_saved_lps(script, path, KILLED_AFTER, poll=0.01)
    with np.load(path) as saved:
        assert KILLED_AFTER <= saved["history_phi"].shape[0] < uninterrupted.iterations
    resumed = jam(start, box="deformable", checkpoint=path)
    assert resumed.category == uninterrupted.category == "strict"
    assert resumed.iterations == uninterrupted.iterations
    np.testing.assert_array_equal(resumed.packing.positions, uninterrupted.packing.positions)
    np.testing.assert_array_equal(resumed.packing.lattice, uninterrupted.packing.lattice)
    np.testing.assert_array_equal(resumed.contacts, uninterrupted.contacts)
    np.testing.assert_array_equal(resumed.wall_contacts, uninterrupted.wall_contacts)
    np.testing.assert_array_equal(resumed.wall_forces, uninterrupted.wall_forces)


@pytest.mark.parametrize("d, boundaries", [
    (2, Boundaries.walls(2, ["x", "y"])), (3, Boundaries.walls(3, ["x", "y", "z"])),
    (2, Boundaries.cylinder(2, ["x", "y"]))])
def test_a_container_without_a_periodic_axis_is_refused_in_one_line(d, boundaries):
    start = random_sequential_addition(32, d, 0.15, seed=1, boundaries=boundaries)
    with pytest.raises(ValueError, match="needs a periodic axis") as refused:
        jam(start, box="deformable")
    assert "\n" not in str(refused.value)


@pytest.mark.parametrize("suffix", [".npz", ".h5"])
def test_a_sheared_container_keeps_its_box_and_walls_in_a_file(runs, tmp_path, suffix):
    _, start, _, from_fixed, from_loose = runs
    for result in (from_fixed, from_loose):
        path = tmp_path / f"result{suffix}"
        write(result, path)
        again = read_result(path)
        assert again.packing.boundaries == start.boundaries
        np.testing.assert_array_equal(again.packing.lattice, result.packing.lattice)
        np.testing.assert_array_equal(again.wall_contacts, result.wall_contacts)
        assert again.isostatic and again.stress_anisotropy <= ISOTROPY
