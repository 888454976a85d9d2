"""The contacts of an interior LP solution, read by strict complementarity.

An interior-point solver stopped without crossover returns a point near the centre of the
optimal face, not a vertex: no dual is exactly zero and no slack either, so a plain
threshold on the duals does not say which rows are contacts. Complementarity does.

Derivation. For every row k of the CALiPPSO LP (`calippso.lp`), write μ_k ≥ 0 for its dual
and s_k = (A x)_k − b_k ≥ 0 for its slack (a length, mean diameters). On the central path
that the interior point follows, every product is the same, μ_k s_k = τ, and τ → 0 as the
duality gap closes. By the Goldman–Tucker theorem the rows split in two: those that carry
a force in some optimal solution (the contacts B: μ_k → μ_k* > 0, so s_k = τ/μ_k → 0) and
those that are open in some optimal solution (N: s_k → s_k* > 0, so μ_k = τ/s_k → 0). The
ratio μ_k/s_k therefore diverges like μ_k*²/τ on B and vanishes like τ/s_k*² on N. Made
dimensionless with a typical contact dual μ̄ and the LP's length scale, its step bound b,

    q_k = log10( (μ_k / μ̄) / (s_k / b) ),    contact  ⇔  q_k > 0.

A contact is misread only when its force is below √(τ μ̄ / b), an open row only when its
slack is below √(τ b / μ̄): both vanish with τ, so the solver's duality gap sets the
resolution (`calippso.solvers.highs.INTERIOR_OPTIMALITY_TOLERANCE`), and |q_k| says by how
many decades each row was read apart (`Reading.margin`).

μ̄ is the dual-weighted mean dual Σ_k c_k μ_k² / Σ_k c_k μ_k, with c_k the row's
coefficient of γ (`LinearProgram.gamma_coefficients`, Σ c_k μ_k = 1 at the optimum): the
duals of open rows are tiny and barely weigh in it, so no threshold is needed to find it.

Ties are decided by the rule alone, in no particular order of the rows: q_k = 0 exactly
(μ_k b = s_k μ̄) is not a contact; a row with μ_k = 0 is never a contact (no force), and a
row with s_k ≤ 0 and μ_k > 0 always is (the solver's round-off can leave a slack a little
below zero).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .lp import LinearProgram
from .solvers import LPSolution

__all__ = ["Reading", "read_complementarity"]


@dataclass(frozen=True, eq=False)
class Reading:
    """The rows of an LP read as contacts, and how clearly.

    Attributes
    ----------
    contacts : ndarray, shape (M + K,), bool
        Row k is a contact (q_k > 0).
    score : ndarray, shape (M + K,)
        q_k = log10((μ_k / μ̄) / (s_k / b)); +inf for μ_k > 0 with s_k ≤ 0, −inf for
        μ_k = 0.
    dual_scale : float
        μ̄, the dual-weighted mean dual.
    slacks : ndarray, shape (M + K,)
        s_k = (A x)_k − b_k (mean diameters).
    """

    contacts: np.ndarray
    score: np.ndarray
    dual_scale: float
    slacks: np.ndarray

    @property
    def margin(self) -> float:
        """min_k |q_k|: decades by which the least clear row was read (inf with no rows)."""
        finite = np.abs(self.score[np.isfinite(self.score)])
        return float(finite.min()) if finite.size else float("inf")


def read_complementarity(lp: LinearProgram, solution: LPSolution) -> Reading:
    """Read the contacts of an interior solution of `lp` by strict complementarity (module
    doc).

    Parameters
    ----------
    lp : LinearProgram
        The LP (rows of pairs, then of walls), with its step bound b.
    solution : LPSolution
        Its answer: displacements and γ in ``x``, duals μ ≥ 0 in the force convention.

    Returns
    -------
    Reading
    """
    duals = np.maximum(solution.duals, 0.0)
    slacks = lp.matrix @ solution.x - lp.row_lower
    weights = lp.gamma_coefficients * duals
    total = float(weights.sum())
    dual_scale = float(weights @ duals) / total if total > 0 else 0.0
    score = np.full(duals.shape, -np.inf)
    positive = duals > 0
    if dual_scale > 0:
        closed = positive & (slacks <= 0)
        score[closed] = np.inf
        open_ = positive & ~closed
        score[open_] = (np.log10(duals[open_] / dual_scale)
                        - np.log10(slacks[open_] / lp.step_bound))
    return Reading(score > 0, score, dual_scale, slacks)
