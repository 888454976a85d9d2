"""Physics of `calippso.jam`: converged, isostatic, overlap-free, balanced, normalised."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import calippso
from calippso import Packing, StopReason, jam
from calippso.history import History, status_sentence
from calippso.geometry.packing import minimum_image

from configurations import bidisperse, overlap_free, random_sequential_addition
from conftest import assert_jammed


@pytest.mark.parametrize(
    "d, n, phi0",
    [(2, 128, 0.45),
     # d = 3 and 4 from far below jamming: test_extremes.py::test_far_from_jamming; d = 5 in
     # the fast suite from an LS start (examples/ls_jam.py --d 5); from random starts d = 5
     # takes hundreds of LPs (45 s at N = 128)
     pytest.param(5, 128, 0.1, marks=pytest.mark.slow),
     pytest.param(5, 256, 0.12, marks=pytest.mark.slow)],
)
def test_jams_random_starts_in_every_dimension(d, n, phi0):
    sizes = bidisperse(n, 1.4) if d == 2 else None
    start = random_sequential_addition(n, d, phi0, seed=d, diameters=sizes)
    result = jam(start)
    assert_jammed(result)
    assert result.phi > phi0


@pytest.mark.slow
def test_compressed_start_from_shared_data(shared_data):
    start = calippso.read(shared_data / "mono_N1000_fba1e-3_then_ls1e-2_seed11")
    result = jam(start, max_iters=400)
    assert_jammed(result)
    assert 0.630 < result.phi < 0.645


def test_positions_diameters_box_signature():
    start = random_sequential_addition(32, 2, 0.4, seed=1, diameters=bidisperse(32))
    a = jam(start)
    b = jam(start.positions, start.diameters, start.box)
    np.testing.assert_array_equal(a.packing.positions, b.packing.positions)
    assert a.n_contacts == b.n_contacts


def test_history_records_every_lp():
    start = random_sequential_addition(64, 3, 0.3, seed=2)
    result = jam(start)
    history = result.history
    assert np.all(np.diff(history["wall_time"]) >= 0)
    assert np.all(history["rows"] > 0)
    assert np.all(history["solver_time"] <= history["wall_time"][-1])
    # density never decreases while the loop runs (the last record may be a clean-up LP)
    assert np.all(np.diff(history["phi"]) >= -1e-15)


def test_result_round_trip(tmp_path):
    start = random_sequential_addition(64, 3, 0.3, seed=3)
    result = jam(start)
    path = result.save(tmp_path / "jammed")
    back = calippso.load_result(path)
    np.testing.assert_array_equal(back.packing.positions, result.packing.positions)
    np.testing.assert_array_equal(back.contacts, result.contacts)
    np.testing.assert_array_equal(back.forces, result.forces)
    for column in result.history.dtype.names:
        np.testing.assert_array_equal(back.history[column], result.history[column])
    assert back.status == result.status and back.converged == result.converged
    assert back.stop_reason is result.stop_reason and back.notes == result.notes
    assert back.isostatic and back.iterations == result.iterations
    assert calippso.read(path).n == 64  # a result file is also a packing file


def test_callback_can_stop_the_run():
    start = random_sequential_addition(64, 3, 0.3, seed=5)
    seen = []

    def stop_after_two(info):
        seen.append(info["iteration"])
        return info["iteration"] >= 2

    result = jam(start, callback=stop_after_two)
    assert seen == [1, 2]
    assert not result.converged and result.stop_reason is StopReason.STOPPED_BY_CALLBACK
    assert overlap_free(result.packing) >= -1e-12


def test_a_stopped_run_takes_its_forces_from_a_cleanup_lp():
    start = random_sequential_addition(64, 3, 0.3, seed=5)
    result = jam(start, callback=lambda info: info["iteration"] >= 5)
    assert result.stop_reason is StopReason.STOPPED_BY_CALLBACK
    assert list(result.history["stage"][-2:]) == ["lp", "cleanup"]
    assert result.iterations == 6


def test_status_quotes_the_last_step_not_the_cleanup_lp():
    history = History(d=3, start=0.0)
    step = dict(solver_time=0.1, rows=10, step_bound=1e-3, n_contacts=4, n_stable=2,
                force_balance=0.0, min_gap=0.0, phi=0.5)
    history.add_lp(stage="lp", gamma=0.02, max_displacement=0.1, **step)
    history.add_lp(stage="cleanup", gamma=0.0, max_displacement=5e-4, **step)
    status = status_sentence(StopReason.STOPPED_BY_CALLBACK, history.lps_solved,
                             history.last_step(), 2, 0, ["a note"])
    last = history.records[0]
    assert status == (f"Stopped by the callback after 2 LPs (sqrt(Gamma)-1 = "
                      f"{last.sqrt_gamma_minus_1:.1e}, max|s| = 1.0e-01); isostatic. "
                      f"Notes: a note.")


def test_status_of_a_run_ended_by_newton():
    result = jam(random_sequential_addition(64, 3, 0.3, seed=5))
    assert result.stop_reason is StopReason.CERTIFIED_NEWTON
    assert result.converged and result.history["stage"][-1] == "newton"
    moved = result.history["max_displacement"][-1]
    assert f"the Newton stage moved stable particles by up to {moved:.1e}" in result.status
    assert result.status.endswith(" Notes: " + "; ".join(result.notes) + ".")


def test_old_result_files_get_their_stop_reason_from_the_status(tmp_path):
    result = jam(random_sequential_addition(64, 3, 0.3, seed=5), max_iters=3)
    arrays = {key: value for key, value in result.to_arrays().items()
              if key not in ("stop_reason", "notes")}
    old = calippso.JammingResult.from_arrays(arrays)
    assert result.stop_reason is old.stop_reason is StopReason.MAX_ITERS
    assert old.notes == [] and old.status == result.status


def test_verbose_prints_a_table(capsys):
    start = random_sequential_addition(32, 2, 0.4, seed=1, diameters=bidisperse(32))
    result = jam(start, verbose=True)
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].split()[:4] == ["#", "stage", "rows", "sqrtG-1"]
    assert len(lines) == len(result.history) + 1


def test_roundoff_overlap_in_input_is_accepted():
    jammed = jam(random_sequential_addition(64, 3, 0.3, seed=6)).packing
    # every contact now overlaps by about 1e-14 sigma, as in files written with few digits
    swollen = Packing(jammed.positions, jammed.diameters * (1 + 1e-14), jammed.box)
    result = jam(swollen)
    assert_jammed(result)
    assert result.phi == pytest.approx(jammed.phi, rel=1e-9)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: (p.positions, p.diameters[:-1], p.box), "diameters has"),
        (lambda p: (np.where(np.arange(p.n)[:, None] == 0, np.nan, p.positions), p.diameters,
                    p.box), "non-finite"),
        (lambda p: (p.positions, p.diameters, p.box[:2]), "box has 2 sides"),
        (lambda p: (p.positions, np.where(np.arange(p.n) == 3, 0.55 * p.box[0], p.diameters),
                    p.box), "box too small"),
    ],
)
def test_bad_input_gives_clear_value_error(make, message):
    start = random_sequential_addition(32, 3, 0.2, seed=8)
    with pytest.raises(ValueError, match=message):
        jam(*make(start))


def test_real_overlap_is_refused():
    start = random_sequential_addition(32, 3, 0.2, seed=9)
    positions = start.positions.copy()
    direction = minimum_image(positions[1] - positions[0], start.box)
    positions[1] = positions[0] + direction / np.linalg.norm(direction) * (1 - 1e-3)
    with pytest.raises(ValueError, match="overlapping particles"):
        jam(Packing(positions, start.diameters, start.box))


def test_duplicated_particle_is_refused():
    start = random_sequential_addition(32, 3, 0.2, seed=9)
    positions = start.positions.copy()
    positions[1] = positions[0]
    with pytest.raises(ValueError, match="duplicated particles.*particles 0 and 1"):
        jam(Packing(positions, start.diameters, start.box))


def test_jam_writes_nothing_to_standard_output():
    """highspy prints a banner when a process builds its first solver object: not to stdout."""
    code = ("import calippso; from configurations import random_sequential_addition; "
            "calippso.jam(random_sequential_addition(32, 3, 0.3, seed=1))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, cwd=Path(__file__).parent)
    assert done.stdout == ""


def test_unconverged_loose_input_points_to_precompression():
    loose = random_sequential_addition(64, 3, 0.3, seed=11)
    result = jam(loose, max_iters=3)
    assert not result.converged and result.stop_reason is StopReason.MAX_ITERS
    assert any(note.startswith("the input is loose")
               and "calippso.protocols.precompress(packing, 1e5)" in note
               for note in result.notes)
    assert not any(note.startswith("the input is loose") for note in jam(loose).notes)
