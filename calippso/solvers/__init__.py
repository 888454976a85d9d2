"""LP backends behind one interface: ``solve(lp, settings, warm_start=None) -> LPSolution``.

The backends never see positions, only the `LinearProgram` data. Each is imported on first
use, so that a user of one backend never loads the others.
"""

from __future__ import annotations

import importlib
from typing import Callable

from .base import Basis, LPSolution

__all__ = ["Basis", "LPSolution", "get_solver"]

_BACKENDS = {"highs": "calippso.solvers.highs", "clarabel": "calippso.solvers.clarabel",
             "cvxpy": "calippso.solvers.cvxpy"}


def get_solver(name: str) -> Callable:
    """The `solve` function of backend `name` ("highs", "clarabel" or "cvxpy")."""
    if name not in _BACKENDS:
        raise ValueError(f"unknown solver {name!r}: choose one of {', '.join(_BACKENDS)}")
    return importlib.import_module(_BACKENDS[name]).solve
