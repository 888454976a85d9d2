"""The loop reads as the algorithm: `calippso.ilp._run` fits on a screen, and each stage of
`calippso.stages` takes the loop's state and returns a new one, leaving its input as it was."""

from __future__ import annotations

import dataclasses
import inspect
import time
from pathlib import Path

import numpy as np
import pytest

import calippso
from calippso import ilp
from calippso.settings import JamSettings
from calippso.stages.lp_step import lp_step
from calippso.stages.newton_stage import TRIED_BEFORE, newton

from configurations import random_sequential_addition

#: Longest `_run`, in source lines (docstring included): about one screen.
RUN_MAX_LINES = 60
#: Longest module of `calippso.stages`, in lines: one job each.
STAGE_MAX_LINES = 250


def _begin(packing: calippso.Packing):
    """The run and the first loop state of `jam(packing)` with the default settings."""
    run, state, _, _ = ilp._start(packing, JamSettings.from_options(), None, None,
                                  time.perf_counter(), None, None)
    return run, state


def test_run_fits_on_a_screen_and_stage_modules_stay_small():
    assert len(inspect.getsource(ilp._run).splitlines()) <= RUN_MAX_LINES
    folder = Path(ilp.__file__).parent / "stages"
    for module in folder.glob("*.py"):
        assert len(module.read_text().splitlines()) <= STAGE_MAX_LINES, module.name
    assert not [name for name, value in vars(ilp).items()
                if inspect.isclass(value) and value.__module__ == ilp.__name__]


def test_an_lp_step_returns_a_new_state_and_leaves_its_input():
    run, state = _begin(random_sequential_addition(64, 3, 0.3, seed=1))
    before = {name: np.copy(getattr(state, name))
              for name in ("positions", "diameters", "forced", "forced_walls")}
    moved, lp = lp_step(run, state)
    for name, value in before.items():
        np.testing.assert_array_equal(getattr(state, name), value)
    assert moved is not state and not np.array_equal(moved.positions, state.positions)
    np.testing.assert_array_equal(moved.search.positions, moved.positions)
    assert lp.record is run.history.last and run.history.lps_solved == 1
    with pytest.raises(dataclasses.FrozenInstanceError):
        moved.step = 1.0


def test_a_refused_network_is_not_tried_again():
    run, state = _begin(random_sequential_addition(64, 3, 0.3, seed=1))
    state, lp = lp_step(run, state)
    refused = state.refused(lp.network.key())
    same, outcome = newton(run, refused, lp.network)
    assert same is refused and outcome.network is None and outcome.failure == TRIED_BEFORE
    assert lp.network.key() not in state.failed_networks
