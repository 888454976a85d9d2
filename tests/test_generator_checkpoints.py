"""Checkpoints of long generator runs (LS, MLS and force-biased spherocylinders): a run killed
between two windows (or steps) loses no finished one, and the resumed run ends bit-for-bit where
the uninterrupted run ends."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import generators
from calippso.geometry.neighbors import min_gap
from generators import diameters as dist
from generators.checkpoint import Checkpoint

REPO = Path(__file__).resolve().parents[1]

from configurations import MLS_ARGS, mls_start

LS_ARGS = dict(d=3, target_pressure=1e12, growth_rate=1e-2, seed=5)


def assert_same(a, b) -> None:
    """Bit-for-bit equality of two generation results (positions, diameters, history)."""
    np.testing.assert_array_equal(a.packing.positions, b.packing.positions)
    np.testing.assert_array_equal(a.packing.diameters, b.packing.diameters)
    np.testing.assert_array_equal(a.packing.box, b.packing.box)
    np.testing.assert_array_equal(a.history, b.history)
    assert a.steps == b.steps
    assert a.reduced_pressure == b.reduced_pressure
    assert a.status == b.status


def assert_no_overlap(packing) -> None:
    gap, overlapping = min_gap(packing.positions, packing.diameters, packing.box)
    assert overlapping == 0 and gap >= -1e-12


#: Runs one generator with a checkpoint in a child process. Each window is followed by a short
#: sleep (it paces the run so that the parent can kill it mid-way; the physics is untouched).
CHILD = textwrap.dedent("""
    import sys, time
    import numpy as np
    import generators
    from generators import diameters as dist
    from generators.ls import GrowingSpheres

    window = GrowingSpheres.window
    def paced(self, *args, **kwargs):
        pressure = window(self, *args, **kwargs)
        time.sleep(0.01)
        return pressure
    GrowingSpheres.window = paced

    kind, path = sys.argv[1], sys.argv[2]
    if kind == "ls":
        generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path,
                                          checkpoint_every=0, **{ls})
    else:
        from configurations import mls_start
        generators.closest_jamming(start=mls_start(), checkpoint=path, checkpoint_every=0, **{mls})
""").format(ls=repr(LS_ARGS), mls=repr(MLS_ARGS))


def run_and_kill(kind: str, path: Path, windows: int) -> int:
    """Start a checkpointed run in a child process, SIGKILL it after `windows` saved windows.

    Returns the number of windows in the checkpoint left behind.
    """
    path_entries = [str(REPO), str(REPO / "tests"), os.environ.get("PYTHONPATH", "")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(path_entries)}
    child = subprocess.Popen([sys.executable, "-c", CHILD, kind, str(path)], env=env,
                             stderr=subprocess.PIPE)
    target = path.with_name(path.name + ".npz")
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline:
            if child.poll() is not None:
                raise AssertionError(f"child ended before it was killed: "
                                     f"{child.stderr.read().decode()[-2000:]}")
            if target.exists():
                with np.load(target) as data:
                    if data["history"].shape[0] >= windows:
                        break
            time.sleep(0.02)
        else:
            raise AssertionError("the child never wrote enough checkpointed windows")
        os.kill(child.pid, signal.SIGKILL)
    finally:
        if child.poll() is None:
            child.kill()
        child.wait()
        child.stderr.close()
    assert child.returncode == -signal.SIGKILL
    with np.load(target) as data:
        return int(data["history"].shape[0])


@pytest.fixture(scope="module")
def ls_reference():
    return generators.lubachevsky_stillinger(dist.monodisperse(64), **LS_ARGS)


@pytest.fixture(scope="module")
def mls_reference(mls_jammed):
    return mls_jammed


def test_ls_killed_with_sigkill_resumes_bit_for_bit(tmp_path, ls_reference):
    path = tmp_path / "ls_run"
    saved = run_and_kill("ls", path, windows=5)
    assert 5 <= saved < ls_reference.history.shape[0]  # killed mid-run, work was kept
    resumed = generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path,
                                                checkpoint_every=0, **LS_ARGS)
    assert resumed.extra["resumed"]
    assert_same(resumed, ls_reference)
    assert resumed.reduced_pressure >= 1e12
    assert_no_overlap(resumed.packing)


@pytest.mark.slow
def test_mls_killed_with_sigkill_resumes_bit_for_bit(tmp_path, mls_reference):
    """... and once finished, the run returns from its checkpoint without recomputing."""
    path = tmp_path / "mls_run"
    # late enough to be past the first pressure threshold (in the rate-decrease phase)
    saved = run_and_kill("mls", path, windows=60)
    assert 60 <= saved < mls_reference.history.shape[0]
    resumed = generators.closest_jamming(start=mls_start(), checkpoint=path, **MLS_ARGS)
    assert resumed.extra["resumed"]
    assert_same(resumed, mls_reference)
    assert resumed.status.startswith("jammed")
    assert_no_overlap(resumed.packing)
    again = generators.closest_jamming(start=mls_start(), checkpoint=path, **MLS_ARGS)
    assert again.extra["resumed"]
    assert_same(again, mls_reference)


def test_finished_run_returns_from_its_checkpoint(tmp_path, ls_reference):
    path = tmp_path / "done.npz"
    first = generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path, **LS_ARGS)
    assert_same(first, ls_reference)
    assert not first.extra["resumed"] and path.exists()
    again = generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path, **LS_ARGS)
    assert again.extra["resumed"]
    assert_same(again, ls_reference)
    assert again.steps == first.steps  # nothing was recomputed


def test_ls_run_can_be_pushed_to_a_higher_pressure(tmp_path, ls_reference):
    """A run stopped at p = 1e5 and continued to 1e12 is the run made at 1e12 directly."""
    path = tmp_path / "staged"
    low = generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path,
                                            **{**LS_ARGS, "target_pressure": 1e5})
    assert 1e5 <= low.reduced_pressure < 1e12
    high = generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path, **LS_ARGS)
    assert_same(high, ls_reference)


def test_ls_slow_end_staged_through_its_slowdown_is_the_direct_run(tmp_path):
    """Stopped before the slowdown pressure and continued past it, a slow-end run is the run
    made directly; the slow rate is part of the run's identity."""
    slow_end = {**LS_ARGS, "target_pressure": 1e4, "final_growth_rate": 1e-3,
                "slowdown_pressure": 1e3}
    direct = generators.lubachevsky_stillinger(dist.monodisperse(64), **slow_end)
    path = tmp_path / "slow_end"
    low = generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path,
                                            **{**slow_end, "target_pressure": 1e2})
    assert np.all(low.history["rate"] == 1e-2)
    high = generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path, **slow_end)
    assert_same(high, direct)
    assert high.history["rate"][-1] == 1e-3
    with pytest.raises(ValueError, match=r"differs in final_growth_rate"):
        generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path,
                                          **{**slow_end, "final_growth_rate": 1e-4})


def test_checkpoint_of_another_run_is_refused(tmp_path):
    path = tmp_path / "other.npz"
    generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path,
                                      **{**LS_ARGS, "target_pressure": 1e3})
    with pytest.raises(ValueError, match=r"checkpoint of another run; it differs in seed"):
        generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path,
                                          **{**LS_ARGS, "seed": 99})
    with pytest.raises(ValueError, match="kind \\(checkpoint 'lubachevsky_stillinger'"):
        generators.closest_jamming(start=mls_start(), checkpoint=path, **MLS_ARGS)


def test_not_a_checkpoint_file_is_refused(tmp_path):
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a zip file at all")
    with pytest.raises(ValueError, match="not a readable generator checkpoint"):
        generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=garbage, **LS_ARGS)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, positions=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="not a generator checkpoint"):
        generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=foreign, **LS_ARGS)


def test_bad_checkpoint_interval_is_refused(tmp_path):
    with pytest.raises(ValueError, match="checkpoint_every"):
        generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=tmp_path / "x",
                                          checkpoint_every=-1, **LS_ARGS)


def test_save_is_atomic_and_leaves_no_temporary_files(tmp_path):
    saver = Checkpoint(tmp_path / "state", "test", {"a": 1}, every=0)
    for k in range(5):
        saver.save({"value": np.arange(k + 1.0)})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.npz"]
    np.testing.assert_array_equal(saver.load()["value"], np.arange(5.0))


# --- force-biased spherocylinders ------------------------------------------------------------

ROD_ARGS = dict(n=300, aspect_ratio=3.0, contraction_rate=3e-3, seed=2)  # 215 steps


class _Crash(Exception):
    """Stands in for a run killed between two steps."""


def test_spherocylinder_run_resumes_bit_for_bit(tmp_path, monkeypatch):
    from generators.spherocylinders import fb

    reference = fb.force_biased(**ROD_ARGS)
    path = tmp_path / "rods.npz"
    real_move, calls = fb._move, []

    def crashing_move(*args):
        calls.append(1)
        if len(calls) == 120:
            raise _Crash
        real_move(*args)

    monkeypatch.setattr(fb, "_move", crashing_move)
    with pytest.raises(_Crash):
        fb.force_biased(**ROD_ARGS, checkpoint=path, checkpoint_every=0)
    assert Checkpoint(path, "spherocylinders.force_biased", {}).path.exists()
    monkeypatch.setattr(fb, "_move", real_move)
    resumed = fb.force_biased(**ROD_ARGS, checkpoint=path, checkpoint_every=0)
    assert reference.steps > 120
    np.testing.assert_array_equal(resumed.packing.positions, reference.packing.positions)
    np.testing.assert_array_equal(resumed.packing.axes, reference.packing.axes)
    for field in reference.history.dtype.names:  # field by field: NaN pressures compare equal
        np.testing.assert_array_equal(resumed.history[field], reference.history[field])
    assert resumed.status == reference.status
    assert resumed.extra["list_builds"] == reference.extra["list_builds"]
    # a finished run is read back, not run again
    again = fb.force_biased(**ROD_ARGS, checkpoint=path)
    np.testing.assert_array_equal(again.packing.positions, reference.packing.positions)
    assert again.steps == reference.steps


def test_spherocylinder_checkpoint_of_another_run_is_refused(tmp_path):
    from generators.spherocylinders import force_biased

    path = tmp_path / "rods.npz"
    force_biased(**{**ROD_ARGS, "contraction_rate": 3e-2}, checkpoint=path)
    with pytest.raises(ValueError, match="contraction_rate"):
        force_biased(**ROD_ARGS, checkpoint=path)
    with pytest.raises(ValueError, match="checkpoint_every"):
        force_biased(**ROD_ARGS, checkpoint=tmp_path / "other.npz", checkpoint_every=-1)


# --- soft-sphere quench ----------------------------------------------------------------------

#: N = 128 in d = 3 tightens its last minimisation over several rounds and pauses.
QUENCH_CASES = {"d3": (dist.monodisperse(128), 3),
                "d2_bidisperse": (dist.bidisperse(64, 1.4), 2)}


def assert_same_quench(a, b) -> None:
    """Bit-for-bit equality of two quench results (history field by field: NaN columns)."""
    np.testing.assert_array_equal(a.packing.positions, b.packing.positions)
    np.testing.assert_array_equal(a.packing.diameters, b.packing.diameters)
    np.testing.assert_array_equal(a.packing.box, b.packing.box)
    np.testing.assert_array_equal(a.contacts, b.contacts)
    for name in a.history.dtype.names:
        np.testing.assert_array_equal(a.history[name], b.history[name])
    assert (a.steps, a.status) == (b.steps, b.status)
    assert a.extra["rebuilds"] == b.extra["rebuilds"]


@pytest.fixture(scope="module")
def quench_references():
    return {(name, minimiser): generators.soft_quench(sizes, d, seed=7, minimiser=minimiser)
            for name, (sizes, d) in QUENCH_CASES.items() for minimiser in ("fire", "lbfgs")}


#: The kernel of each minimiser, and the position of the force tolerance in its arguments.
QUENCH_KERNELS = {"fire": ("_fire", "fire_run", 15), "lbfgs": ("_lbfgs", "lbfgs_run", 14)}


@pytest.mark.parametrize("minimiser", ["fire", "lbfgs"])
@pytest.mark.parametrize("case, crash", [
    ("d3", ("steps", 0.3)),
    pytest.param("d3", ("steps", 0.7), marks=pytest.mark.slow),
    ("d3", ("tightening", 3)),
    pytest.param("d2_bidisperse", ("steps", 0.3), marks=pytest.mark.slow),
    pytest.param("d2_bidisperse", ("steps", 0.8), marks=pytest.mark.slow)])
def test_quench_killed_mid_minimisation_resumes_bit_for_bit(tmp_path, monkeypatch, case,
                                                            crash, minimiser,
                                                            quench_references):
    """Killed after a fraction of its steps (an early or a late rung), or at the third
    stretch of steps of the tightening rounds, the quench resumes from its checkpoint
    and ends where the uninterrupted run ends (FIRE, and L-BFGS with its history). Both
    runs pause every 100 steps instead of 1000: pauses change no result either."""
    import importlib

    from generators.soft_quench import INTERMEDIATE_TOLERANCE

    monkeypatch.setattr(importlib.import_module("generators.soft_quench"), "PAUSE_STEPS", 100)
    module_name, kernel, tolerance_at = QUENCH_KERNELS[minimiser]
    module = importlib.import_module(f"generators.{module_name}")
    sizes, d = QUENCH_CASES[case]
    reference = quench_references[case, minimiser]
    real_run, taken, tightening = getattr(module, kernel), [], []
    kind, where = crash

    def crashing_run(*args):
        tolerance = args[tolerance_at]
        tightening.extend([1] if tolerance < INTERMEDIATE_TOLERANCE else [])
        if (sum(taken) >= where * reference.steps if kind == "steps"
                else len(tightening) == where):
            raise _Crash
        result = real_run(*args)
        taken.append(result[1])
        return result

    monkeypatch.setattr(module, kernel, crashing_run)
    path = tmp_path / "quench.npz"
    with pytest.raises(_Crash):
        generators.soft_quench(sizes, d, seed=7, checkpoint=path, checkpoint_every=0,
                               minimiser=minimiser)
    with np.load(path) as saved:
        assert saved["state_method"].size        # saved in the middle of a minimisation
        assert (int(saved["run_round"]) > 0) == (kind == "tightening")
        if minimiser == "lbfgs":                 # with the history of the minimisation
            assert np.any(saved["state_memory_x"])
    monkeypatch.setattr(module, kernel, real_run)
    resumed = generators.soft_quench(sizes, d, seed=7, checkpoint=path, checkpoint_every=0,
                                     minimiser=minimiser)
    assert resumed.extra["resumed"]
    assert_same_quench(resumed, reference)
    # a finished run is read back, not run again
    monkeypatch.setattr(module, kernel, None)
    again = generators.soft_quench(sizes, d, seed=7, checkpoint=path, minimiser=minimiser)
    assert_same_quench(again, reference)


@pytest.mark.parametrize("minimiser", ["fire", "lbfgs"])
def test_quench_stopped_by_max_steps_continues_with_a_larger_limit(tmp_path, minimiser,
                                                                   quench_references):
    """A quench stopped by `max_steps` says so, and called again with more steps it becomes
    the run made with them from the start. FIRE stops at the limit; L-BFGS finishes the line
    search in progress."""
    from generators._lbfgs import LINE_SEARCH_EVALUATIONS

    sizes, d = QUENCH_CASES["d3"]
    reference = quench_references["d3", minimiser]
    limit = reference.steps // 2
    path = tmp_path / "staged.npz"
    stopped = generators.soft_quench(sizes, d, seed=7, max_steps=limit, checkpoint=path,
                                     minimiser=minimiser)
    assert stopped.status.startswith(f"stopped at max_steps = {limit}")
    overshoot = 0 if minimiser == "fire" else LINE_SEARCH_EVALUATIONS
    assert limit <= stopped.steps <= limit + overshoot
    same = generators.soft_quench(sizes, d, seed=7, max_steps=limit, checkpoint=path,
                                  minimiser=minimiser)
    assert_same_quench(same, stopped)
    finished = generators.soft_quench(sizes, d, seed=7, checkpoint=path, minimiser=minimiser)
    assert_same_quench(finished, reference)


def test_quench_checkpoint_of_another_run_is_refused(tmp_path):
    sizes, d = QUENCH_CASES["d3"]
    path = tmp_path / "quench.npz"
    generators.soft_quench(sizes, d, seed=7, max_steps=500, checkpoint=path, minimiser="fire")
    with pytest.raises(ValueError, match=r"quench\.npz: checkpoint of another run; it differs "
                                         r"in seed \(checkpoint 7, this call 8\)"):
        generators.soft_quench(sizes, d, seed=8, checkpoint=path, minimiser="fire")
    with pytest.raises(ValueError, match=r"differs in target_pressure"):
        generators.soft_quench(sizes, d, seed=7, target_pressure=3e-7, checkpoint=path,
                               minimiser="fire")
    with pytest.raises(ValueError, match=r"differs in minimiser"):
        generators.soft_quench(sizes, d, seed=7, minimiser="lbfgs", checkpoint=path)
    with pytest.raises(ValueError, match="checkpoint_every"):
        generators.soft_quench(sizes, d, seed=7, checkpoint=path, checkpoint_every=-1,
                               minimiser="fire")


@pytest.mark.parametrize("minimiser", ["fire", "lbfgs"])
def test_walled_quench_killed_mid_minimisation_resumes_bit_for_bit(tmp_path, monkeypatch,
                                                                   minimiser):
    """Between flat walls (bidisperse discs, walls in x and y) a quench killed half-way through
    its steps resumes from its checkpoint and ends where the uninterrupted run ends, wall
    contacts and boundaries included; the checkpoint is refused by the periodic run."""
    import importlib

    from calippso import Boundaries

    walls = Boundaries.walls(2, ["x", "y"])
    sizes, d = QUENCH_CASES["d2_bidisperse"]
    reference = generators.soft_quench(sizes, d, seed=7, minimiser=minimiser, boundaries=walls)
    module_name, kernel, _ = QUENCH_KERNELS[minimiser]
    module = importlib.import_module(f"generators.{module_name}")
    real_run, taken = getattr(module, kernel), []

    def crashing_run(*args):
        if sum(taken) >= 0.5 * reference.steps:
            raise _Crash
        result = real_run(*args)
        taken.append(result[1])
        return result

    monkeypatch.setattr(module, kernel, crashing_run)
    path = tmp_path / "walled.npz"
    with pytest.raises(_Crash):
        generators.soft_quench(sizes, d, seed=7, checkpoint=path, checkpoint_every=0,
                               minimiser=minimiser, boundaries=walls)
    monkeypatch.setattr(module, kernel, real_run)
    resumed = generators.soft_quench(sizes, d, seed=7, checkpoint=path, checkpoint_every=0,
                                     minimiser=minimiser, boundaries=walls)
    assert resumed.extra["resumed"]
    assert_same_quench(resumed, reference)
    assert resumed.packing.boundaries == walls
    np.testing.assert_array_equal(resumed.extra["wall_contacts"],
                                  reference.extra["wall_contacts"])
    with pytest.raises(ValueError, match="differs in boundaries"):
        generators.soft_quench(sizes, d, seed=7, checkpoint=path, minimiser=minimiser)


def test_walled_ls_pushed_to_a_higher_pressure_is_the_direct_run(tmp_path):
    """Between walls (in x and z) an LS run stopped at p = 1e3 and continued to 1e6 from its
    checkpoint is the run made at 1e6 directly, bit for bit, walls included; the checkpoint
    is refused by the periodic run."""
    from calippso import Boundaries

    walls = Boundaries.walls(3, ["x", "z"])
    args = {**LS_ARGS, "target_pressure": 1e6, "boundaries": walls}
    direct = generators.lubachevsky_stillinger(dist.monodisperse(64), **args)
    path = tmp_path / "walled_ls"
    low = generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path,
                                            **{**args, "target_pressure": 1e3})
    assert 1e3 <= low.reduced_pressure < 1e6
    high = generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path, **args)
    assert high.extra["resumed"]
    assert_same(high, direct)
    assert high.packing.boundaries == walls
    with pytest.raises(ValueError, match="differs in boundaries"):
        generators.lubachevsky_stillinger(dist.monodisperse(64), checkpoint=path,
                                          **{**args, "boundaries": None})
