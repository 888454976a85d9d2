"""The LP in the conic form of interior-point solvers: minimise qᵀx s.t. A x + slack = b, slack ∈ K.

Fixed columns (the pin, frozen rattlers) are dropped, so the backends only see free variables.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..lp import LinearProgram


@dataclass(frozen=True, eq=False)
class ConicForm:
    """`LinearProgram` as A x ≤ b (all rows non-negative slack), free columns only.

    Attributes
    ----------
    matrix : scipy.sparse.csc_matrix
        Rows: the M pair rows (negated), then upper bounds, then lower bounds.
    rhs : ndarray
    cost : ndarray
        −1 on γ (minimise −γ), 0 elsewhere.
    free : ndarray, bool, shape (N d + 1,)
        Which columns of the original LP are variables here.
    n_pair_rows : int
        M; the first M duals are the pair multipliers.
    """

    matrix: sp.csc_matrix
    rhs: np.ndarray
    cost: np.ndarray
    free: np.ndarray
    n_pair_rows: int

    def full_x(self, x: np.ndarray) -> np.ndarray:
        """Expand a solution over free columns to all N d + 1 columns (fixed ones are 0)."""
        full = np.zeros(self.free.shape[0])
        full[self.free] = x
        return full


def conic_form(lp: LinearProgram) -> ConicForm:
    """Rewrite `lp` as A x ≤ b with free columns only (see `ConicForm`)."""
    free = lp.col_upper > lp.col_lower
    pair_block = lp.matrix[:, free]
    lower, upper = lp.col_lower[free], lp.col_upper[free]
    identity = sp.identity(int(free.sum()), format="csc")
    has_upper = np.isfinite(upper)
    matrix = sp.vstack([-pair_block, identity[has_upper], -identity]).tocsc()
    rhs = np.concatenate([-lp.row_lower, upper[has_upper], -lower])
    cost = np.zeros(int(free.sum()))
    cost[-1] = -1.0
    return ConicForm(matrix, rhs, cost, free, lp.n_rows)
