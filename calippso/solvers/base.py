"""The result every LP backend returns."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LPSolution", "Basis"]


@dataclass(frozen=True, eq=False)
class Basis:
    """An optimal simplex basis, with each row named by its pair, so that the next LP of the
    loop (other positions, partly other rows) can start from it.

    Attributes
    ----------
    row_keys : ndarray, shape (M,), int64
        i N + j for the pair (i, j) of every row.
    row_status, col_status : ndarray, shapes (M,) and (N d + 1,), int8
        The backend's status code of every row and column (basic, at lower, at upper, ...).
    """

    row_keys: np.ndarray
    row_status: np.ndarray
    col_status: np.ndarray


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
    basis : Basis or None
        The optimal basis, for a warm start of the next LP (HiGHS only).
    warm_started : bool
        The solution was found from the previous LP's basis.
    ipm_iterations : int
        Interior-point iterations the backend took (0 when it reports none, or when a
        warm-started simplex solved the LP).
    """

    x: np.ndarray
    duals: np.ndarray
    optimal: bool
    status: str
    seconds: float
    vertex: bool
    solver: str
    basis: Basis | None = None
    warm_started: bool = False
    ipm_iterations: int = 0

    @property
    def gamma(self) -> float:
        """γ* = Γ* − 1."""
        return float(self.x[-1])
