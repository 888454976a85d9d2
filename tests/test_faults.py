"""Solver failure injection: backends that raise, or return garbage, at chosen LPs.

A wrapper around a real backend (registered in its place, `replace_backend` in conftest.py)
corrupts its answers from a given LP on. The loop must reject every corrupted answer, retry
and fall back, and still end jammed; when nothing works, the `JammingError` keeps the last
valid configuration (the one after the last accepted LP) and the history so far. Only a
`SolverError` counts as a backend failure: any other exception is a bug and reaches the caller.
This is the one place where retries and fallbacks are tested.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from calippso import JammingError, jam
from calippso.errors import SolverError
from calippso.solvers import LPAttempt, get_backend

from configurations import overlap_free, random_sequential_addition
from conftest import assert_jammed


def _nan_x(solution):
    x = solution.x.copy()
    x[0] = np.nan
    return replace(solution, x=x)


def _short_x(solution):
    return replace(solution, x=solution.x[:-3])


def _huge_gamma(solution):
    x = solution.x.copy()
    x[-1] = 10.0   # Γ − 1 = 10: every contact row violated (spheres would overlap)
    return replace(solution, x=x)


def _scaled_duals(solution):
    return replace(solution, duals=solution.duals * 3.0)   # Σ λ σ² = 3, not 1


def _not_optimal(solution):
    return replace(solution, optimal=False, status="infeasible (injected)")


def _raise(solution):
    raise SolverError("injected backend crash")


GARBAGE = {"nan": _nan_x, "wrong-size": _short_x, "rows-violated": _huge_gamma,
           "bad-normalisation": _scaled_duals, "not-optimal": _not_optimal, "crash": _raise}


class Injector:
    """A backend wrapping the real backend `target`: its answers are corrupted by `fault` at
    LPs start … stop (1-based).

    Attributes
    ----------
    calls : list of (name, lp_number)
        Every backend call of the run, in order (from ``jam(..., on_lp=injector.record)``).
    """

    def __init__(self, target: str, fault, start: int = 1, stop: float = np.inf,
                 only_first_try: bool = False):
        self.inner = get_backend(target)
        self.name, self.options_type = target, self.inner.options_type
        self.fault, self.start, self.stop = fault, start, stop
        self.only_first_try = only_first_try
        self.calls: list[tuple[str, int]] = []
        self.accepted = 0          # LPs accepted so far, from the callback of `jam`
        self.tries = Counter()     # calls of this backend at each LP

    def callback(self, info: dict) -> None:
        self.accepted = info["iteration"]

    def record(self, attempt: LPAttempt) -> None:
        self.calls.append((attempt.backend, attempt.lp_number))

    def options(self, settings):
        return self.inner.options(settings)

    def validate(self, options) -> None:
        self.inner.validate(options)

    def solve(self, lp, options, warm_start=None):
        current = self.accepted + 1
        self.tries[current] += 1
        solution = self.inner.solve(lp, options, warm_start=warm_start)
        broken = self.start <= current <= self.stop
        if broken and self.only_first_try:
            broken = self.tries[current] == 1
        return self.fault(solution) if broken else solution


@pytest.fixture(scope="module")
def start():
    return random_sequential_addition(48, 3, 0.3, seed=12)


@pytest.mark.parametrize("fault", list(GARBAGE), ids=list(GARBAGE))
def test_garbage_from_the_main_backend_is_rejected_and_replaced(replace_backend, start, fault):
    """Every answer of HiGHS at LP 3 is corrupted: both tries are refused, Clarabel solves
    LP 3, HiGHS takes over again at LP 4, and the packing ends jammed."""
    injector = Injector("highs", GARBAGE[fault], start=3, stop=3)
    replace_backend(injector)
    result = jam(start, callback=injector.callback, on_lp=injector.record)
    assert_jammed(result)
    assert any(note.startswith("LP 3 needed a retry (clarabel") for note in result.notes)
    # highs was tried twice (bound, then bound / 4) at LP 3 before the fallback
    assert injector.calls.count(("highs", 3)) == 2
    assert ("clarabel", 3) in injector.calls
    assert ("highs", 4) in injector.calls


def test_persistently_failing_backend_falls_back(replace_backend, start):
    """HiGHS crashes at every LP from LP 3 on: Clarabel carries the run to the end (the step
    bound adapts from the LP actually solved, and the notes name the first retry and count
    the others, without a note per LP)."""
    injector = Injector("highs", _raise, start=3)
    replace_backend(injector)
    result = jam(start, callback=injector.callback, max_iters=150)
    assert_jammed(result)
    assert result.solver == "clarabel"
    retries = [note for note in result.notes if "retry" in note]
    assert len(retries) == 2
    assert retries[0].startswith("LP 3 needed a retry (clarabel")
    assert retries[1].endswith("LPs in all needed a retry")


def test_transient_failure_is_retried_with_the_same_backend(replace_backend, start):
    injector = Injector("highs", _raise, start=2, only_first_try=True)
    replace_backend(injector)
    result = jam(start, callback=injector.callback, on_lp=injector.record)
    assert_jammed(result)
    assert result.solver == "highs"
    assert any(note.startswith("LP 2 needed a retry (highs") for note in result.notes)
    assert not any(name == "clarabel" for name, _ in injector.calls)


@pytest.mark.parametrize("fault", ["nan", "rows-violated", "crash"])
def test_every_backend_failing_midway_keeps_the_last_valid_configuration(replace_backend,
                                                                         start, fault):
    """HiGHS and Clarabel both fail from LP 4 on."""
    seen = {}
    injectors = [Injector(name, GARBAGE[fault], start=4) for name in ("highs", "clarabel")]
    for injector in injectors:
        replace_backend(injector)

    def remember(info):
        seen[info["iteration"]] = info["packing"]
        for injector in injectors:
            injector.callback(info)

    with pytest.raises(JammingError, match=r"every LP backend failed at LP 4") as caught:
        jam(start, callback=remember)
    error = caught.value
    last = seen[3]
    assert error.packing is not None
    np.testing.assert_array_equal(error.packing.positions, last.positions)
    np.testing.assert_array_equal(error.packing.diameters, last.diameters)
    assert overlap_free(error.packing) >= -1e-12
    assert error.packing.phi > start.phi
    assert np.count_nonzero(error.history["stage"] == "lp") == 3
    # the message names every attempt: the main backend twice, then the fallback twice
    assert str(error).count("highs (bound") == 2 and str(error).count("clarabel (bound") == 2


def test_error_from_the_first_lp_keeps_the_input(replace_backend, start):
    for name in ("highs", "clarabel"):
        replace_backend(Injector(name, _raise))
    with pytest.raises(JammingError, match="SolverError: injected backend crash") as caught:
        jam(start)
    np.testing.assert_allclose(caught.value.packing.positions, start.wrapped().positions,
                               rtol=0, atol=1e-15 * start.box.max())
    np.testing.assert_allclose(caught.value.packing.diameters, start.diameters, rtol=1e-15)


def test_a_bug_in_a_backend_is_not_taken_for_a_solver_failure(replace_backend, start):
    """Only `SolverError` is a backend failure: another exception raised in a backend ends the
    run as it is, without retries or fallbacks that would hide it."""
    def bug(solution):
        raise KeyError("a bug, not a solver failure")

    injector = Injector("highs", bug, start=2)
    replace_backend(injector)
    with pytest.raises(KeyError, match="a bug, not a solver failure"):
        jam(start, callback=injector.callback, on_lp=injector.record)
    assert injector.tries[2] == 1
    assert all(name == "highs" for name, _ in injector.calls)


def test_time_of_refused_attempts_is_counted(replace_backend, start):
    """Attempts that fail still took solver time: it goes into the history record of the LP
    that was finally taken, so that the solver time adds up to the time spent solving."""
    pause = 0.2

    def slow_crash(solution):
        import time

        time.sleep(pause)
        raise SolverError("injected backend crash after a pause")

    injector = Injector("highs", slow_crash, start=3, stop=3)
    replace_backend(injector)
    result = jam(start, callback=injector.callback, on_lp=injector.record)
    lps = result.history[result.history["stage"] == "lp"]
    assert injector.calls.count(("highs", 3)) == 2
    assert lps["solver_time"][2] >= 2 * pause
    assert np.all(np.delete(lps["solver_time"], 2) < pause)
