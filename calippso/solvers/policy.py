"""Which backend the loop asks, with which bound and warm start, which answers it takes, and
what it tells ``jam(..., on_lp=...)``.

Every LP is tried by the chosen backend at the step bound, then at a quarter of it, then by
each fallback backend in the same two ways (`attempt_plan`), until an answer passes the checks
of `solution_problem`. The backends of a run are looked up, given their options and validated
once, before any LP (`prepare_backends`). `SolverPolicy` carries out that plan for the loop:
it builds each try's LP through a function of the bound (it never sees positions), offers the
previous basis as a warm start (`next_warm_start` chooses it), solves an LP again from
scratch when the loop asks (`SolverPolicy.cold_resolve`), and counts the solver time of the
answers not taken.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..errors import SolverError
from .backend import Backend
from .base import Basis, LPSolution
from .registry import check_backend_name, get_backend

if TYPE_CHECKING:
    from ..lp import LinearProgram
    from ..settings import JamSettings

__all__ = ["Attempt", "LPAttempt", "PreparedBackend", "SolvedLP", "SolverPolicy", "LPFailed",
           "attempt_plan", "prepare_backends", "solution_problem", "next_warm_start",
           "RETRY_BOUND_DIVISOR", "COLD_START_DISPLACEMENT"]

#: A retry solves the LP again with the step bound divided by this (fewer rows, a smaller
#: and better conditioned problem).
RETRY_BOUND_DIVISOR = 4.0
#: An answer is refused when a pair row is violated by more than this (mean diameters).
ROW_VIOLATION_TOLERANCE = 1e-7
#: ... or when its duals miss the normalisation Σ λ σ² = 1 by more than this.
DUAL_NORMALIZATION_TOLERANCE = 1e-6
#: The next LP starts cold when a stable particle moved by this fraction of the bound or more
#: (`next_warm_start`).
COLD_START_DISPLACEMENT = 0.5

#: `Attempt.role` and `LPAttempt.role` values.
FIRST, RETRY, FALLBACK, COLD_RESOLVE = "first", "retry", "fallback", "cold resolve"


@dataclass(frozen=True)
class Attempt:
    """One planned try at an LP: which backend, with which bound on the displacements.

    Attributes
    ----------
    backend : str
        Registered backend name.
    bound : float
        Bound on every displacement component (mean diameters).
    role : str
        "first", "retry" (the chosen backend at a smaller bound) or "fallback" (another
        backend).
    """

    backend: str
    bound: float
    role: str


def attempt_plan(solver: str, fallback_solvers: tuple[str, ...], step: float) -> list[Attempt]:
    """The tries at one LP, in order: `solver` at `step`, then at ``step / RETRY_BOUND_DIVISOR``,
    then every fallback other than `solver` at the same two bounds."""
    smaller = step / RETRY_BOUND_DIVISOR
    plan = [Attempt(solver, step, FIRST), Attempt(solver, smaller, RETRY)]
    plan += [Attempt(name, bound, FALLBACK) for name in fallback_solvers if name != solver
             for bound in (step, smaller)]
    return plan


def solution_problem(lp: "LinearProgram", solution: LPSolution) -> str | None:
    """Why a backend's answer to `lp` cannot be used, or None when it passes the checks:
    optimal status, the right sizes, finite values, rows satisfied to
    `ROW_VIOLATION_TOLERANCE`, duals normalised to `DUAL_NORMALIZATION_TOLERANCE`."""
    if not solution.optimal:
        return f"status '{solution.status}'"
    if solution.x.shape[0] != lp.n_cols or solution.duals.shape[0] != lp.n_rows:
        return "solution of the wrong size"
    if not (np.all(np.isfinite(solution.x)) and np.all(np.isfinite(solution.duals))):
        return "non-finite values in the solution"
    violation = float(np.min(lp.matrix @ solution.x - lp.row_lower, initial=0.0))
    if violation < -ROW_VIOLATION_TOLERANCE:
        return f"rows violated by {-violation:.2e}"
    normalization = float(solution.duals @ lp.gamma_coefficients)
    if abs(normalization - 1.0) > DUAL_NORMALIZATION_TOLERANCE:
        return f"dual normalisation sum(lambda sigma^2) = {normalization:.3e}, not 1"
    return None


@dataclass(frozen=True)
class PreparedBackend:
    """A backend with the options of this run.

    Attributes
    ----------
    backend : Backend
    options : object
        An instance of ``backend.options_type``.
    """

    backend: Backend
    options: Any

    def solve(self, lp: "LinearProgram", warm_start: Basis | None = None) -> LPSolution:
        """Solve `lp` (see `Backend.solve`); raises `calippso.errors.SolverError` on failure."""
        return self.backend.solve(lp, self.options, warm_start=warm_start)


def prepare_backends(settings: "JamSettings") -> dict[str, PreparedBackend]:
    """The chosen backend and the fallbacks of `settings`, each with its options, validated.

    Every name is checked against the registry before any backend's module is imported.

    Raises
    ------
    ValueError
        If a name is not registered (the message names it, as the solver or a fallback
        solver, and the registered names), or if a backend cannot run with these settings
        here (e.g. ``interior_point="hipo"`` without the HiPO build of HiGHS), before any LP
        is built.
    """
    check_backend_name(settings.solver, "solver")
    for name in settings.fallback_solvers:
        check_backend_name(name, "fallback solver")
    prepared = {}
    for name in (settings.solver, *settings.fallback_solvers):
        if name in prepared:
            continue
        backend = get_backend(name)
        options = backend.options(settings)
        backend.validate(options)
        prepared[name] = PreparedBackend(backend, options)
    return prepared


@dataclass(frozen=True, eq=False)
class LPAttempt:
    """One backend call of the loop, as handed to ``jam(..., on_lp=...)``.

    Attributes
    ----------
    lp_number : int
        The LP of the run this call is for (1-based; counts the LPs of the loop and the force
        clean-up LP, as `JammingResult.iterations` does).
    role : str
        "first", "retry" (the chosen backend at a smaller bound), "fallback" (another
        backend) or "cold resolve" (the LP solved again from scratch after a warm-started
        vertex gave a hypostatic network).
    backend : str
        The backend's name.
    lp : LinearProgram
        The LP as the backend received it.
    warm_start : Basis or None
        The basis the backend was offered.
    solution : LPSolution or None
        The backend's answer; None when it raised `calippso.errors.SolverError`.
    failure : str or None
        Why the loop refused the answer (the error, or the check it failed); None when the
        solution passed the loop's checks.
    """

    lp_number: int
    role: str
    backend: str
    lp: "LinearProgram"
    warm_start: Basis | None
    solution: LPSolution | None
    failure: str | None

    @property
    def accepted(self) -> bool:
        """The solution passed the loop's checks."""
        return self.failure is None


class LPFailed(Exception):
    """Every try of `attempt_plan` failed on an LP; the message says how each one failed."""


@dataclass(frozen=True, eq=False)
class SolvedLP:
    """The answer the loop takes for one LP.

    Attributes
    ----------
    lp : LinearProgram
        The LP as solved (at the bound of the successful try).
    solution : LPSolution
    attempt : Attempt
        The try that succeeded.
    warm_start : Basis or None
        The basis that try was offered.
    note : str or None
        For the run's notes: the first LP of the run that needed a retry, and why.
    """

    lp: "LinearProgram"
    solution: LPSolution
    attempt: Attempt
    warm_start: Basis | None
    note: str | None


class SolverPolicy:
    """The backends of one run and the rules by which the loop uses them.

    Parameters
    ----------
    settings : JamSettings
        ``solver``, ``fallback_solvers`` and ``warm_start`` are used here; the backends get
        their options from all of it (`prepare_backends`).
    on_lp : callable, optional
        Called with an `LPAttempt` after every backend call (see `calippso.jam`).

    Attributes
    ----------
    retried_lps : int
        LPs that needed more than the first try so far.
    """

    def __init__(self, settings: "JamSettings",
                 on_lp: Callable[[LPAttempt], None] | None = None) -> None:
        self.settings = settings
        self.on_lp = on_lp
        self.backends = prepare_backends(settings)
        self.retried_lps = 0
        self._discarded_seconds = 0.0

    def solve(self, build_lp: Callable[[float], "LinearProgram"], step: float,
              basis: Basis | None, lp_number: int) -> SolvedLP:
        """Solve LP number `lp_number`: the tries of `attempt_plan` in order, until an answer
        passes `solution_problem`.

        Parameters
        ----------
        build_lp : callable
            The LP at a given bound on the displacements (mean diameters).
        step : float
            The bound of the first try.
        basis : Basis or None
            Offered to the first try as a warm start (if ``settings.warm_start``); retries
            start from scratch.
        lp_number : int
            1-based, for `LPAttempt` and the notes.

        Raises
        ------
        LPFailed
            When every try failed.
        """
        failures = []
        warm_start = basis if self.settings.warm_start else None
        for attempt in attempt_plan(self.settings.solver, self.settings.fallback_solvers, step):
            lp = build_lp(attempt.bound)
            solution, failure = self._call(attempt.backend, lp, warm_start, attempt.role,
                                           lp_number)
            if failure is None:
                note = None
                if attempt.role != FIRST:
                    if not self.retried_lps:
                        note = (f"LP {lp_number} needed a retry ({attempt.backend}, bound "
                                f"{attempt.bound:.1e}) after: {'; '.join(failures)}")
                    self.retried_lps += 1
                return SolvedLP(lp, solution, attempt, warm_start, note)
            failures.append(f"{attempt.backend} (bound {attempt.bound:.1e}): {failure}")
            warm_start = None   # retries start from scratch
        raise LPFailed(f"every LP backend failed at LP {lp_number}: " + "; ".join(failures))

    def cold_resolve(self, solved: SolvedLP, lp_number: int) -> LPSolution | None:
        """The same LP solved again from scratch by the backend that solved it, or None if
        that fails. The answer's time includes the first solution's.

        At a degenerate optimum (crystalline patches, nearly redundant contacts) the simplex
        from an old basis can end at a vertex whose duals leave out contacts; interior point
        + crossover ends near the centre of the optimal face and keeps them. The loop asks
        for this when a warm-started vertex gave a hypostatic network.
        """
        cold, failure = self._call(solved.attempt.backend, solved.lp, None, COLD_RESOLVE,
                                   lp_number)
        if failure is not None:
            return None
        return replace(cold, seconds=cold.seconds + solved.solution.seconds)

    def discard(self, seconds: float) -> None:
        """Count the solver time of an answer the loop did not take."""
        self._discarded_seconds += seconds

    def take_discarded_seconds(self) -> float:
        """The solver time of the answers not taken since the last call (and reset it)."""
        seconds, self._discarded_seconds = self._discarded_seconds, 0.0
        return seconds

    def _call(self, name: str, lp: "LinearProgram", warm_start: Basis | None, role: str,
              lp_number: int) -> tuple[LPSolution | None, str | None]:
        """One backend call: its solution and None, or what failed (the backend's
        `SolverError`, or the check its solution failed).

        Only `SolverError` is caught: any other exception is a bug and ends the run. The time
        of a refused call is discarded (`take_discarded_seconds`); ``on_lp`` sees every call.
        """
        began = time.perf_counter()
        try:
            solution = self.backends[name].solve(lp, warm_start)
        except SolverError as error:
            solution, failure = None, f"{type(error).__name__}: {error}"
            self.discard(time.perf_counter() - began)
        else:
            failure = solution_problem(lp, solution)
            if failure is not None:
                self.discard(solution.seconds)
        if self.on_lp is not None:
            self.on_lp(LPAttempt(lp_number, role, name, lp, warm_start, solution, failure))
        return solution, failure


def next_warm_start(solution: LPSolution, offered: bool, max_displacement: float,
                    bound: float) -> Basis | None:
    """The basis the next LP starts from, or None for a cold start.

    A warm start pays off when consecutive LPs differ little. It does not when a stable
    particle moved by `COLD_START_DISPLACEMENT` of the bound or more (the particles still
    travel far, so the next optimal basis is far from this one), nor right after a warm start
    that failed (the next LP is then solved cold, and the one after tries again).

    Parameters
    ----------
    solution : LPSolution
        The answer taken for the last LP.
    offered : bool
        That LP was offered a warm start.
    max_displacement : float
        Its largest displacement of a stable particle (mean diameters).
    bound : float
        Its bound on the displacements (mean diameters).
    """
    warm_failed = offered and not solution.warm_started
    if warm_failed or max_displacement >= COLD_START_DISPLACEMENT * bound:
        return None
    return solution.basis
