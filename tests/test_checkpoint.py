"""jam(..., checkpoint=path): state saved after every LP, exact resumption, even after SIGKILL."""

import re

import numpy as np
import pytest
from configurations import random_sequential_addition
from conftest import assert_jammed, kill_after_saved_lps

from calippso import jam


def start_configuration():
    """A loose start (φ = 0.3) that takes ~50 LPs to jam (N = 64, d = 3; ~1 s)."""
    return random_sequential_addition(64, 3, 0.3, seed=5)


@pytest.fixture(scope="module")
def uninterrupted():
    return jam(start_configuration())


class Crash(Exception):
    """Stands for anything that ends a process in the middle of a run."""


def assert_same_result(resumed, reference):
    np.testing.assert_array_equal(resumed.packing.positions, reference.packing.positions)
    np.testing.assert_array_equal(resumed.packing.diameters, reference.packing.diameters)
    np.testing.assert_array_equal(resumed.contacts, reference.contacts)
    np.testing.assert_array_equal(resumed.forces, reference.forces)
    assert resumed.iterations == reference.iterations
    np.testing.assert_array_equal(resumed.history["phi"], reference.history["phi"])


def test_resumed_run_gives_the_uninterrupted_result(tmp_path, uninterrupted):
    path = tmp_path / "state.npz"

    def crash_after_five(record):
        if record["iteration"] == 5:
            raise Crash

    with pytest.raises(Crash):
        jam(start_configuration(), checkpoint=path, callback=crash_after_five)
    assert path.exists()
    with np.load(path) as saved:
        assert saved["history_phi"].shape[0] == 4  # state after LP 4; LP 5 never saved
    resumed = jam(start_configuration(), checkpoint=path)
    assert_jammed(resumed)
    assert_same_result(resumed, uninterrupted)


def test_run_killed_by_sigkill_resumes(tmp_path, uninterrupted):
    path = tmp_path / "killed.npz"
    script = (
        "from configurations import random_sequential_addition\n"
        "from calippso import jam\n"
        f"jam(random_sequential_addition(64, 3, 0.3, seed=5), checkpoint={str(path)!r})\n")
    kill_after_saved_lps(script, path, 8)
    resumed = jam(start_configuration(), checkpoint=path)
    assert_jammed(resumed)
    assert_same_result(resumed, uninterrupted)


def test_checkpoint_of_another_input_is_refused(tmp_path):
    path = tmp_path / "other.npz"

    def stop(record):
        return record["iteration"] == 2

    jam(random_sequential_addition(32, 2, 0.4, seed=1), checkpoint=path, callback=stop)
    with pytest.raises(ValueError, match="checkpoint of another run; it differs in input "):
        jam(start_configuration(), checkpoint=path)
    with pytest.raises(ValueError, match=r"it differs in step_growth \(checkpoint 4.0, this "
                                         r"call 3.0\)"):
        jam(random_sequential_addition(32, 2, 0.4, seed=1), checkpoint=path, step_growth=3.0)


def test_a_file_that_is_not_a_checkpoint_is_refused(tmp_path):
    path = tmp_path / "junk.npz"
    np.savez(path, positions=np.zeros((3, 2)))
    with pytest.raises(ValueError, match="not a jam checkpoint"):
        jam(start_configuration(), checkpoint=path)


def test_a_checkpoint_of_the_old_layout_is_refused_in_one_line(tmp_path):
    """Jam checkpoints written before jam shared the generators' checkpoint design (keys
    "signature" and "format_version") are refused, naming the file."""
    path = tmp_path / "old.npz"
    np.savez(path, signature=np.array("abc"), format_version=np.array(2),
             positions=np.zeros((3, 2)))
    expected = f"^{re.escape(str(path))}: a jam checkpoint of an older calippso"
    with pytest.raises(ValueError, match=expected) as error:
        jam(start_configuration(), checkpoint=path)
    assert "\n" not in str(error.value)
