"""The result every LP backend returns."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LPSolution"]


@dataclass(frozen=True, eq=False)
class LPSolution:
    """Primal and dual solution of one `LinearProgram`.

    Attributes
    ----------
    x : ndarray, shape (N d + 1,)
        Displacements s (flattened, particle-major) followed by γ = Γ − 1.
    duals : ndarray, shape (M,)
        Row multipliers μ ≥ 0 in the force convention (μ_ij = 2 f_ij).
    optimal : bool
        The backend reported an optimal solution.
    status : str
        The backend's own status text.
    seconds : float
        Wall time inside the backend (model transfer included).
    vertex : bool
        True for a basic (vertex) solution, whose inactive duals are exactly zero.
    solver : str
        Backend name.
    """

    x: np.ndarray
    duals: np.ndarray
    optimal: bool
    status: str
    seconds: float
    vertex: bool
    solver: str

    @property
    def gamma(self) -> float:
        """γ* = Γ* − 1."""
        return float(self.x[-1])
