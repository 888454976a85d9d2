"""The `Backend` protocol: what an LP backend gives the CALiPPSO loop.

A backend solves one `LinearProgram` (maximise γ subject to the pair rows and the bounds on
the displacements) and returns an `LPSolution`. It never sees positions, only the LP data.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from .base import Basis, LPSolution

if TYPE_CHECKING:
    from ..lp import LinearProgram
    from ..settings import JamSettings

__all__ = ["Backend"]


@runtime_checkable
class Backend(Protocol):
    """An LP backend, as registered with `calippso.solvers.register_backend`.

    Attributes
    ----------
    name : str
        The name users pass as ``jam(..., solver=name)`` or in ``fallback_solvers``.
    options_type : type
        The backend's options dataclass (its tolerances and method choices, with documented
        defaults); `options` builds one from the run's `JamSettings`.

    Notes
    -----
    `solve` raises `calippso.errors.SolverError` when the backend fails (the library raised,
    ran out of memory, or gave no answer); the loop then retries and falls back to the next
    backend. Any other exception is a bug and ends the run. A solution that the backend
    returns but that is not optimal (``optimal=False``) or fails the loop's own checks is
    retried in the same way.
    """

    name: str
    options_type: type

    def options(self, settings: "JamSettings") -> Any:
        """The backend's options for a run with `settings`."""

    def validate(self, options: Any) -> None:
        """Raise ValueError, before any LP is built, if the backend cannot run with `options`
        here (e.g. a method this build of the library lacks)."""

    def solve(self, lp: "LinearProgram", options: Any, warm_start: Basis | None = None
              ) -> LPSolution:
        """Solve `lp`; `warm_start` is the previous LP's optimal basis, which a backend
        without simplex ignores. Raises `calippso.errors.SolverError` on failure."""
