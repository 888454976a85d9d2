"""LP backends behind one protocol (`Backend`) and one registry (`register_backend`).

The backends never see positions, only the `LinearProgram` data. A built-in backend's
module, and its LP library, is imported when a run uses it, as the chosen solver or as a
fallback (`get_backend`); listing the names imports none.

Adding a backend: write an object with ``name``, ``options_type`` (a dataclass),
``options(settings)``, ``validate(options)`` and ``solve(lp, options, warm_start=None)``
that raises `SolverError` when it fails, and pass it to `register_backend`. It is then
accepted by ``jam(..., solver=...)``, in ``fallback_solvers`` and by the CLI.
"""

from __future__ import annotations

from typing import Callable

from ..errors import SolverError
from .backend import Backend
from .base import Basis, LPSolution
from .policy import LPAttempt
from .registry import backend_names, check_backend_name, get_backend, register_backend

__all__ = ["Backend", "Basis", "LPAttempt", "LPSolution", "SolverError", "backend_names",
           "check_backend_name", "get_backend", "get_solver", "register_backend"]


def get_solver(name: str) -> Callable[..., LPSolution]:
    """A function ``solve(lp, settings, warm_start=None) -> LPSolution`` that solves with
    backend `name`, its options built from the `JamSettings` `settings`.

    Raises
    ------
    ValueError
        If no backend of that name is registered.
    """
    backend = get_backend(name)

    def solve(lp, settings, warm_start: Basis | None = None) -> LPSolution:
        return backend.solve(lp, backend.options(settings), warm_start=warm_start)

    return solve
