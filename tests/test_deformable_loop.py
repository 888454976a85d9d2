"""jam(box="deformable") runs the loop of the fixed box: checkpoints and exact resumption
(even after SIGKILL), the time limit, the network hint, on_lp and progress lines."""

import numpy as np
import pytest
from configurations import random_sequential_addition
from conftest import kill_after_saved_lps

import lattices
from calippso import StopReason, jam
from calippso.deformable import strain_count

#: The loose start of these tests: N = 64 spheres at φ = 0.3 (d = 3), which a deformable
#: run takes to a strictly jammed packing in about 70 LPs (~2 s).
START = "random_sequential_addition(64, 3, 0.3, seed=5)"


def start_configuration():
    return random_sequential_addition(64, 3, 0.3, seed=5)


@pytest.fixture(scope="module")
def uninterrupted():
    return jam(start_configuration(), box="deformable")


class Crash(Exception):
    """Stands for anything that ends a process in the middle of a run."""


def assert_same_result(resumed, reference):
    assert resumed.box_mode == "deformable" and resumed.category == reference.category
    np.testing.assert_array_equal(resumed.packing.positions, reference.packing.positions)
    np.testing.assert_array_equal(resumed.packing.diameters, reference.packing.diameters)
    np.testing.assert_array_equal(resumed.packing.lattice, reference.packing.lattice)
    np.testing.assert_array_equal(resumed.contacts, reference.contacts)
    np.testing.assert_array_equal(resumed.forces, reference.forces)
    np.testing.assert_array_equal(resumed.stress, reference.stress)
    assert resumed.iterations == reference.iterations
    assert resumed.stop_reason == reference.stop_reason
    np.testing.assert_array_equal(resumed.history["phi"], reference.history["phi"])


def test_the_loose_start_ends_strictly_jammed_by_the_strict_newton_stage(uninterrupted):
    assert uninterrupted.stop_reason == StopReason.CERTIFIED_NEWTON
    assert uninterrupted.category == "strict" and uninterrupted.iterations > 20
    assert uninterrupted.packing.is_sheared


def test_resumed_run_gives_the_uninterrupted_result(tmp_path, uninterrupted):
    path = tmp_path / "state.npz"

    def crash_after_ten(record):
        if record["iteration"] == 10:
            raise Crash

    with pytest.raises(Crash):
        jam(start_configuration(), box="deformable", checkpoint=path,
            callback=crash_after_ten)
    with np.load(path) as saved:
        assert saved["history_phi"].shape[0] == 9   # state after LP 9; LP 10 never saved
        assert saved["cell"].shape == (3, 3)
    assert_same_result(jam(start_configuration(), box="deformable", checkpoint=path),
                       uninterrupted)


def test_run_killed_by_sigkill_resumes(tmp_path, uninterrupted):
    path = tmp_path / "killed.npz"
    script = ("from configurations import random_sequential_addition\n"
              "from calippso import jam\n"
              f"jam({START}, box='deformable', checkpoint={str(path)!r})\n")
    kill_after_saved_lps(script, path, 15, poll=0.02)
    with np.load(path) as saved:
        solved = saved["history_phi"].shape[0]
    assert 15 <= solved < uninterrupted.iterations
    assert_same_result(jam(start_configuration(), box="deformable", checkpoint=path),
                       uninterrupted)


def test_a_fixed_box_checkpoint_is_not_resumed_by_a_deformable_run(tmp_path):
    path = tmp_path / "fixed.npz"
    jam(start_configuration(), checkpoint=path, callback=lambda record: record["iteration"] == 3)
    with pytest.raises(ValueError, match="checkpoint of another run"):
        jam(start_configuration(), box="deformable", checkpoint=path)


def test_time_limit_stops_the_deformable_loop():
    result = jam(start_configuration(), box="deformable", time_limit=1e-3)
    assert result.stop_reason == StopReason.TIME_LIMIT and not result.converged
    assert result.iterations == 1 and result.box_mode == "deformable"
    assert result.category is None


@pytest.fixture(scope="module")
def strict_isostatic():
    """An LS input of 64 discs (50:50, ratio 1.4) and its deformable run, which ends with a
    strictly isostatic network certified by the strict Newton stage after 6 LPs."""
    import generators

    start = generators.lubachevsky_stillinger(generators.diameters.bidisperse(64), d=2,
                                              target_pressure=1e5, seed=0).packing
    return start, jam(start, box="deformable")


def test_a_network_hint_is_certified_by_the_strict_newton_stage_with_no_lp(strict_isostatic):
    _, jammed = strict_isostatic
    assert jammed.isostaticity_gap == 0
    hinted = jam(jammed.packing, box="deformable", network=jammed.contacts)
    assert hinted.iterations == 0 and hinted.stop_reason == StopReason.NETWORK_FIRST
    assert hinted.category == "strict" and hinted.converged
    assert hinted.phi == pytest.approx(jammed.phi, abs=1e-12)
    np.testing.assert_array_equal(hinted.contacts, jammed.contacts)


def test_a_hint_refused_by_the_strict_newton_stage_leaves_the_run_to_the_lps(strict_isostatic):
    start, jammed = strict_isostatic
    hinted = jam(start, box="deformable", network=jammed.contacts)
    # from the input, the rattlers sit where the strict point's cage overlaps them
    assert any("network hint was refused" in note for note in hinted.notes)
    assert hinted.iterations == jammed.iterations and hinted.phi == jammed.phi


def test_a_hint_short_of_the_strict_count_is_left_to_the_lps():
    packing = lattices.triangular(4)
    jammed = jam(packing, box="deformable")
    result = jam(packing, box="deformable", network=jammed.contacts[1:])
    assert result.iterations >= 1 and result.category == "strict"
    assert any("network hint was not tried" in note for note in result.notes)
    with pytest.raises(Exception, match="network_first='require'"):
        jam(packing, box="deformable", network=jammed.contacts[1:], network_first="require")


def test_on_lp_sees_the_strain_columns_and_verbose_prints_every_lp(capsys):
    attempts = []
    packing = lattices.kagome(2)
    result = jam(packing, box="deformable", on_lp=attempts.append, verbose=True)
    assert len([a for a in attempts if a.accepted]) == result.iterations
    n, d = packing.n, packing.d
    assert all(a.lp.n_cols == n * d + strain_count(d) + 1 for a in attempts)
    assert len(capsys.readouterr().out.splitlines()) >= result.iterations
