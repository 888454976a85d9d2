"""LP backends (`calippso.solvers`): the registry, the options and validation of each backend,
the ``on_lp`` hook, and the backend matrix: every backend jams the extreme inputs (far from
jamming, nearly jammed, a crystal) with every invariant, repeatably. Retries and fallbacks
are tested in tests/test_faults.py.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np
import pytest

import calippso
import calippso.solvers.highs as highs
import lattices
from calippso import JamSettings, jam
from calippso.errors import SolverError
from calippso.solvers import (LPAttempt, backend_names, get_backend, get_solver,
                              register_backend)
from calippso.solvers.clarabel import ClarabelOptions
from calippso.solvers.highs import HighsOptions
from configurations import overlap_free, phi_j, random_sequential_addition
from conftest import assert_jammed, assert_rigid_and_balanced, jam_digest

BUILT_IN = ("highs", "clarabel", "cvxpy")


@pytest.fixture(scope="module")
def small_start():
    """N = 32 spheres in d = 3 at φ = 0.3: a few LPs with any backend."""
    return random_sequential_addition(32, 3, 0.3, seed=1)


# ----------------------------------------------------------------------------- registry

def test_built_in_backends_are_registered_first():
    assert backend_names()[:3] == BUILT_IN
    for name in BUILT_IN:
        backend = get_backend(name)
        assert backend.name == name
        options = backend.options(JamSettings())
        assert isinstance(options, backend.options_type)


@pytest.mark.parametrize("options, pattern", [
    (dict(solver="gurobi"), r"^unknown solver 'gurobi': choose one of highs, clarabel, cvxpy"),
    (dict(fallback_solvers=("highs", "clarable")),
     r"^unknown fallback solver 'clarable': choose one of highs, clarabel, cvxpy"),
], ids=["solver", "fallback"])
def test_unknown_backend_names_are_refused_when_jam_starts(small_start, options, pattern):
    """Settings hold any name (a backend may be registered later); jam checks the names
    against the registry before any LP."""
    settings = JamSettings(**options)
    assert {name: getattr(settings, name) for name in options} == options
    with pytest.raises(ValueError, match=pattern):
        jam(small_start, **options)


def test_unknown_interior_point_is_refused_when_settings_are_built():
    with pytest.raises(ValueError, match=r"^unknown interior_point 'simplex'"):
        JamSettings(interior_point="simplex")


def test_fallback_solvers_must_be_a_sequence_of_names():
    with pytest.raises(TypeError, match="not the string 'clarabel'"):
        JamSettings(fallback_solvers="clarabel")
    assert JamSettings(fallback_solvers=["clarabel"]).fallback_solvers == ("clarabel",)


def test_register_backend_refuses_incomplete_objects_and_taken_names():
    with pytest.raises(TypeError, match="not an LP backend: .* lacks options_type, options, "
                                        "validate, solve"):
        register_backend(SimpleNamespace(name="half"))
    with pytest.raises(ValueError, match="'highs' is already registered"):
        register_backend(get_backend("highs"))


def test_cli_offers_the_registered_backends():
    from calippso.cli import cli

    for command in ("jam", "ensemble"):
        option = next(p for p in cli.commands[command].params if p.name == "solver")
        assert tuple(option.type.choices) == backend_names()


@dataclass(frozen=True)
class Renamed:
    """A backend registered under another name that delegates to a built-in one."""

    name: str
    inner: object

    @property
    def options_type(self) -> type:
        return self.inner.options_type

    def options(self, settings):
        return self.inner.options(settings)

    def validate(self, options) -> None:
        self.inner.validate(options)

    def solve(self, lp, options, warm_start=None):
        return replace(self.inner.solve(lp, options, warm_start), solver=self.name)


def test_a_registered_backend_is_accepted_by_jam_and_as_a_fallback(small_start,
                                                                   replace_backend):
    """A backend added with `register_backend` jams by its name, and serves as a fallback."""
    backend = Renamed("highs-renamed", get_backend("highs"))
    replace_backend(backend)   # registers the new name; removed again after the test
    result = jam(small_start, solver="highs-renamed", fallback_solvers=("highs-renamed",))
    assert_jammed(result)
    assert result.solver == "highs-renamed"


# ----------------------------------------------------------------------------- options

def test_highs_options_come_from_the_settings():
    settings = JamSettings(feasibility_tolerance=1e-9, interior_point="ipx")
    options = get_backend("highs").options(settings)
    assert options == HighsOptions(feasibility_tolerance=1e-9, interior_point="ipx")
    assert get_backend("clarabel").options(settings) == ClarabelOptions()
    assert get_backend("cvxpy").options(settings) == ClarabelOptions()


@pytest.mark.parametrize("interior_point", ["ipx", "hipo"])
def test_both_interior_points_jam(small_start, interior_point):
    """HiPO (with the hipo extra) jams like IPX; without it, the run is refused before any LP
    by the HiGHS backend's validation. No warm starts, so that every LP is solved by the
    interior point under test."""
    if interior_point == "hipo" and not highs.hipo_available():
        with pytest.raises(ValueError, match=r"HiPO needs the highspy-extras package"):
            jam(small_start, interior_point="hipo")
        with pytest.raises(ValueError, match=r"HiPO needs the highspy-extras package"):
            jam(small_start, solver="clarabel", fallback_solvers=("highs",),
                interior_point="hipo")
        return
    assert_jammed(jam(small_start, interior_point=interior_point, warm_start=False))


def test_auto_interior_point_takes_hipo_for_large_lps_only(monkeypatch):
    """"auto" picks HiPO from HIPO_MIN_COLUMNS columns on where it is installed, IPX
    otherwise; N = 1024 in d = 3 and 4 stays with IPX."""
    small = SimpleNamespace(n_cols=highs.HIPO_MIN_COLUMNS - 1)
    large = SimpleNamespace(n_cols=highs.HIPO_MIN_COLUMNS)
    assert 4 * 1024 + 1 < highs.HIPO_MIN_COLUMNS <= 3 * 2048 + 1
    assert highs.interior_point_for(large, "ipx") == "ipx"
    assert highs.interior_point_for(small, "hipo") == "hipo"
    monkeypatch.setattr(highs, "hipo_available", lambda: True)
    assert highs.interior_point_for(small, "auto") == "ipx"
    assert highs.interior_point_for(large, "auto") == "hipo"
    monkeypatch.setattr(highs, "hipo_available", lambda: False)
    assert highs.interior_point_for(large, "auto") == "ipx"


# ----------------------------------------------------------------------------- failures

def first_lp(start):
    """The first LP of `jam` on `start`, as ``on_lp`` hands it over."""
    seen: list[LPAttempt] = []
    jam(start, max_iters=1, on_lp=seen.append)
    return seen[0].lp


class _OutOfMemory:
    """Stands in for a `highspy.Highs` object whose solve runs out of memory."""

    def __getattr__(self, name):
        return lambda *args, **kwargs: highs.highspy.HighsStatus.kOk

    def run(self):
        raise MemoryError("std::bad_alloc")


@pytest.mark.parametrize("budget, expected", [("3", 3), ("1", 1), (" 2 ", 2)])
def test_highs_runs_on_the_thread_budget_of_the_process(monkeypatch, budget, expected):
    """OMP_NUM_THREADS (an ensemble worker's share of the cores) sets HiGHS's threads."""
    monkeypatch.setenv("OMP_NUM_THREADS", budget)
    assert highs.highs_threads() == expected
    assert highs._quiet_highs().getOptionValue("threads")[1] == expected


@pytest.mark.parametrize("budget", [None, "", "0", "two"])
def test_without_a_thread_budget_highs_takes_every_core_of_the_process(monkeypatch, budget):
    import os

    if budget is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", budget)
    cores = (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
             else os.cpu_count())
    assert highs.highs_threads() == cores


def test_library_errors_become_solver_errors(small_start, monkeypatch):
    """What a library raises while solving is a `SolverError` (the loop falls back on it);
    the message names the library and the original error."""
    lp = first_lp(small_start)
    monkeypatch.setattr(highs, "_quiet_highs", _OutOfMemory)
    with pytest.raises(SolverError, match="HiGHS raised MemoryError: std::bad_alloc"):
        get_solver("highs")(lp, JamSettings())

    import calippso.solvers.clarabel as clarabel_backend

    def crash(*args):
        raise RuntimeError("factorisation failed")

    monkeypatch.setattr(clarabel_backend.clarabel, "DefaultSolver", crash)
    with pytest.raises(SolverError, match="Clarabel raised RuntimeError: factorisation failed"):
        get_solver("clarabel")(lp, JamSettings())


# ----------------------------------------------------------------------------- on_lp

def test_on_lp_sees_every_lp_of_the_run(small_start):
    """One accepted call per LP of the history, on the LP whose rows the history records, and
    the γ* of its solution is the growth the history records."""
    seen: list[LPAttempt] = []
    result = jam(small_start, on_lp=seen.append, newton=False)
    accepted = {a.lp_number: a for a in seen if a.accepted}   # the last one of each LP
    assert list(accepted) == list(range(1, result.iterations + 1))
    assert all(a.backend == "highs" for a in accepted.values())
    history = result.history[np.isin(result.history["stage"], ["lp", "cleanup"])]
    np.testing.assert_array_equal([a.lp.n_rows for a in accepted.values()], history["rows"])
    growth = np.array([np.sqrt(1 + a.solution.gamma) - 1 for a in accepted.values()])
    lp_stage = history["stage"] == "lp"
    np.testing.assert_allclose(growth[lp_stage], history["sqrt_gamma_minus_1"][lp_stage],
                               rtol=1e-12, atol=0)
    # a warm start offered to an LP is the optimal basis of the LP before it
    for number, attempt in accepted.items():
        if attempt.warm_start is not None:
            assert attempt.warm_start is accepted[number - 1].solution.basis


def test_an_exception_raised_by_on_lp_reaches_the_caller(small_start):
    class Enough(Exception):
        pass

    def stop(attempt: LPAttempt) -> None:
        raise Enough(attempt.lp_number)

    with pytest.raises(Enough, match="1"):
        jam(small_start, on_lp=stop)


# ----------------------------------------------------------------------------- the matrix

@pytest.fixture(scope="module")
def far_from_jamming():
    """Case 2 of the extreme matrix: N = 64, d = 3 at φ = 0.3 φ_J."""
    return random_sequential_addition(64, 3, 0.3 * phi_j(3), seed=8)


@pytest.mark.parametrize("solver", BUILT_IN)
def test_every_backend_jams_far_from_jamming_repeatably(solver, far_from_jamming):
    """Jammed with every invariant; a second run gives the same packing bit for bit."""
    result = jam(far_from_jamming, solver=solver)
    assert_jammed(result)
    assert result.solver == solver
    assert jam_digest(jam(far_from_jamming, solver=solver)) == jam_digest(result)


@pytest.mark.parametrize("solver", BUILT_IN)
def test_every_backend_jams_a_nearly_jammed_input(solver, nearly_jammed):
    result = jam(nearly_jammed, solver=solver)
    assert_jammed(result)
    assert result.solver == solver
    assert result.phi == pytest.approx(nearly_jammed.phi, rel=1e-5)


@pytest.mark.parametrize("solver", BUILT_IN)
def test_every_backend_finds_every_contact_of_a_crystal(solver):
    """FCC, 2 × 2 × 2 cells, just below contact: every one of the 12 N / 2 lattice contacts
    is found, hyperstatic."""
    start = lattices.fcc(2, fill=0.99)
    result = jam(start, solver=solver)
    assert_rigid_and_balanced(result)
    assert result.n_contacts == lattices.CONTACTS_PER_PARTICLE["fcc"] * start.n // 2
    assert result.isostaticity_gap > 0
    assert result.phi == pytest.approx(start.phi / 0.99**3, rel=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("solver", BUILT_IN)
def test_skoge_donev_p1e12_every_backend(shared_data, solver):
    start = calippso.read(shared_data / "skoge_donev_N1000_d3_p1e12.dat")
    assert start.n == 1000 and overlap_free(start) > -1e-14   # round-off only
    result = jam(start, solver=solver)
    assert_jammed(result)
    assert result.solver == solver
    # measured (HiGHS): 125 LPs, phi 0.638386 -> 0.639050 (117 LPs and 0.639156 with
    # earlier step-bound rules); the file's p = 1e12 state is not at its jamming point
    assert start.phi <= result.phi < 0.645


@pytest.mark.slow
@pytest.mark.parametrize("solver", ["clarabel", "cvxpy"])
def test_far_from_jamming_d5_other_backends(solver):
    start = random_sequential_addition(64, 5, 0.3 * phi_j(5), seed=15)
    result = jam(start, solver=solver)
    assert_jammed(result)
