"""Which backend the loop asks, with which bound, which answers it takes, and what it tells
``jam(..., on_lp=...)``.

Every LP is tried by the chosen backend at the step bound, then at a quarter of it, then by
each fallback backend in the same two ways (`attempt_plan`), until an answer passes the checks
of `solution_problem`. The backends of a run are looked up, given their options and validated
once, before any LP (`prepare_backends`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .backend import Backend
from .base import Basis, LPSolution
from .registry import get_backend

if TYPE_CHECKING:
    from ..lp import LinearProgram
    from ..settings import JamSettings

__all__ = ["Attempt", "LPAttempt", "PreparedBackend", "attempt_plan", "prepare_backends",
           "solution_problem", "RETRY_BOUND_DIVISOR"]

#: A retry solves the LP again with the step bound divided by this (fewer rows, a smaller
#: and better conditioned problem).
RETRY_BOUND_DIVISOR = 4.0
#: An answer is refused when a pair row is violated by more than this (mean diameters).
ROW_VIOLATION_TOLERANCE = 1e-7
#: ... or when its duals miss the normalisation Σ λ σ² = 1 by more than this.
DUAL_NORMALIZATION_TOLERANCE = 1e-6

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

    Raises
    ------
    ValueError
        If a backend cannot run with these settings here (e.g. ``interior_point="hipo"``
        without the HiPO build of HiGHS), before any LP is built.
    """
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
