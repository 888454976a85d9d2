"""Solver failure injection: backends that raise, or return garbage, at chosen LPs.

A wrapper around the real backends (patched in as `calippso.ilp.get_solver`) corrupts the
answers of one backend from a given LP on. The loop must reject every corrupted answer, retry
and fall back, and still end jammed; when nothing works, the `JammingError` keeps the last
valid configuration (the one after the last accepted LP) and the history so far.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import calippso.solvers as solvers
from calippso import JammingError, jam

from configurations import overlap_free, random_sequential_addition
from test_extremes import assert_jammed

REAL = solvers.get_solver


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
    raise RuntimeError("injected backend crash")


def _memory(solution):
    raise MemoryError("injected out of memory")


GARBAGE = {"nan": _nan_x, "wrong-size": _short_x, "rows-violated": _huge_gamma,
           "bad-normalisation": _scaled_duals, "not-optimal": _not_optimal, "crash": _raise,
           "out-of-memory": _memory}


class Injector:
    """`get_solver` replacement: backend `target` is corrupted by `fault` at LPs start … stop.

    Attributes
    ----------
    calls : list of (name, lp_index)
        Every backend call, in order (lp_index counts accepted LPs before the call).
    """

    def __init__(self, target: str, fault, start: int = 1, stop: float = np.inf,
                 only_first_try: bool = False):
        self.target, self.fault, self.start, self.stop = target, fault, start, stop
        self.only_first_try = only_first_try
        self.calls: list[tuple[str, int]] = []
        self.accepted = 0   # updated by the callback of `jam`

    def callback(self, info: dict) -> None:
        self.accepted = info["iteration"]

    def __call__(self, name: str):
        real = REAL(name)

        def solve(lp, settings, warm_start=None):
            self.calls.append((name, self.accepted + 1))
            solution = real(lp, settings, warm_start=warm_start)
            current = self.accepted + 1
            broken = name == self.target and self.start <= current <= self.stop
            if broken and self.only_first_try:
                broken = sum(1 for c in self.calls if c == (name, current)) == 1
            return self.fault(solution) if broken else solution

        return solve


@pytest.fixture(scope="module")
def start():
    return random_sequential_addition(48, 3, 0.3, seed=12)


@pytest.mark.parametrize("fault", list(GARBAGE), ids=list(GARBAGE))
def test_garbage_from_the_main_backend_is_rejected_and_replaced(monkeypatch, start, fault):
    """Every answer of HiGHS at LP 3 is corrupted: both tries are refused, Clarabel solves
    LP 3, HiGHS takes over again at LP 4, and the packing ends jammed."""
    injector = Injector("highs", GARBAGE[fault], start=3, stop=3)
    monkeypatch.setattr("calippso.ilp.get_solver", injector)
    result = jam(start, callback=injector.callback)
    assert_jammed(result)
    assert "LP 3 needed a retry (clarabel" in result.status
    # highs was tried twice (bound, then bound / 4) at LP 3 before the fallback
    assert injector.calls.count(("highs", 3)) == 2
    assert ("clarabel", 3) in injector.calls
    assert ("highs", 4) in injector.calls


def test_persistently_failing_backend_falls_back(monkeypatch, start):
    """HiGHS crashes at every LP from LP 3 on: Clarabel carries the run to the end (the step
    bound adapts from the LP actually solved, and the status stays short)."""
    injector = Injector("highs", _raise, start=3)
    monkeypatch.setattr("calippso.ilp.get_solver", injector)
    result = jam(start, callback=injector.callback, max_iters=150)
    assert_jammed(result)
    assert result.solver == "clarabel"
    assert len(result.status) < 2000


def test_transient_failure_is_retried_with_the_same_backend(monkeypatch, start):
    injector = Injector("highs", _raise, start=2, only_first_try=True)
    monkeypatch.setattr("calippso.ilp.get_solver", injector)
    result = jam(start, callback=injector.callback)
    assert_jammed(result)
    assert result.solver == "highs"
    assert "retry" in result.status
    assert not any(name == "clarabel" for name, _ in injector.calls)


@pytest.mark.parametrize("fault", ["nan", "rows-violated", "crash"])
def test_every_backend_failing_midway_keeps_the_last_valid_configuration(monkeypatch, start,
                                                                         fault):
    seen = {}

    def remember(info):
        seen[info["iteration"]] = info["packing"]

    injector = Injector("any", GARBAGE[fault], start=4)
    injector.target = None

    def all_broken(name):
        real = REAL(name)

        def solve(lp, settings, warm_start=None):
            solution = real(lp, settings, warm_start=warm_start)
            return GARBAGE[fault](solution) if len(seen) >= 3 else solution
        return solve

    monkeypatch.setattr("calippso.ilp.get_solver", all_broken)
    with pytest.raises(JammingError, match=r"every LP backend failed at LP 4") as caught:
        jam(start, callback=remember)
    error = caught.value
    last = seen[3]
    assert error.packing is not None
    np.testing.assert_array_equal(error.packing.positions, last.positions)
    np.testing.assert_array_equal(error.packing.diameters, last.diameters)
    assert overlap_free(error.packing) >= -1e-12
    assert error.packing.phi > start.phi
    lps = error.history[error.history["kind"] == "lp"] if "kind" in error.history.dtype.names \
        else error.history
    assert len(lps) == 3
    # the message names every attempt: the main backend twice, then the fallback
    assert str(error).count("highs") >= 2 and "clarabel" in str(error)


def test_error_from_the_first_lp_keeps_the_input(monkeypatch, start):
    def broken(name):
        def solve(lp, settings, warm_start=None):
            raise RuntimeError("injected failure")
        return solve

    monkeypatch.setattr("calippso.ilp.get_solver", broken)
    with pytest.raises(JammingError, match="injected failure") as caught:
        jam(start)
    np.testing.assert_allclose(caught.value.packing.positions, start.wrapped().positions,
                               rtol=0, atol=1e-15 * start.box.max())
    np.testing.assert_allclose(caught.value.packing.diameters, start.diameters, rtol=1e-15)


def test_time_of_refused_attempts_is_counted(monkeypatch, start):
    """Attempts that fail still took solver time: it goes into the history record of the LP
    that was finally taken, so that the solver time adds up to the time spent solving."""
    pause = 0.2

    def slow_crash(solution):
        import time

        time.sleep(pause)
        raise RuntimeError("injected backend crash after a pause")

    injector = Injector("highs", slow_crash, start=3, stop=3)
    monkeypatch.setattr("calippso.ilp.get_solver", injector)
    result = jam(start, callback=injector.callback)
    lps = result.history[result.history["stage"] == "lp"]
    assert injector.calls.count(("highs", 3)) == 2
    assert lps["solver_time"][2] >= 2 * pause
    assert np.all(np.delete(lps["solver_time"], 2) < pause)
