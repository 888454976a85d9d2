"""The records of a pivot path and the factorisation its pivots share.

`Swap` is one pivot, `PivotPath` the end of a path; `Vertex` is a point of the path (an
isostatic network at its Newton point) and `Basis` the sparse LU that the pivots after it
reuse, one swapped row at a time, through the Woodbury identity. `describe_path` writes the
clause of a run's notes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import lu_factor, lu_solve

from ..newton import Refinement
from ..sparse_lu import Factors, Tally

__all__ = ["Swap", "PivotPath", "Vertex", "Basis", "describe_path", "DEGENERATE_STEP",
           "MAX_ROW_SWAPS", "MAX_SMALL_CONDITION", "LISTED_SWAPS"]

#: An inflation step (relative, ΔΓ/Γ) below this is a degenerate pivot: the closing pair
#: already touches, Γ does not grow.
DEGENERATE_STEP = 1e-14
#: Rows swapped into one factorisation (`Basis`) before the Jacobian is factorised again.
MAX_ROW_SWAPS = 40
#: The k × k system of the Woodbury identity, its rows scaled to unit size, is refused beyond
#: this condition number (its solves would lose the accuracy that the chord steps and
#: refinement need).
MAX_SMALL_CONDITION = 1e10
#: Swaps listed by name in `describe_path`.
LISTED_SWAPS = 5


@dataclass(frozen=True)
class Swap:
    """One pivot: the contact released, the pair closed, and the inflation gained.

    Attributes
    ----------
    released : tuple of int
        The contact (i, j) whose force was not positive.
    closed : tuple of int
        The pair (i, j) that closed along the floppy mode.
    growth : float
        √(Γ'/Γ) − 1: the relative diameter growth of this pivot (0 when degenerate).
    new_rattlers : int
        Particles the release left with d contacts (they leave the network).
    rejoined : int
        Rattlers whose cage closed along the floppy mode first (k of them join the network
        with the k d + 1 pairs that closed; `closed` is the first of those).
    non_positive : int
        Contacts whose force is still not positive at the vertex this pivot reached.
    seconds : float
        Wall time of this pivot (the releases tried, the ratio test and Newton).
    """

    released: tuple[int, int]
    closed: tuple[int, int]
    growth: float
    new_rattlers: int
    rejoined: int = 0
    non_positive: int = 0
    seconds: float = 0.0


@dataclass(frozen=True, eq=False)
class PivotPath:
    """The end of a pivot path: an isostatic network at its Newton point, with positive forces
    (`jammed`), or the last vertex that the path reached before it had to stop.

    Attributes
    ----------
    i, j : ndarray, shape (M,), int64
        Contacts between stable particles, i < j.
    rattlers : ndarray, shape (N,), bool
    refinement : Refinement
        The jamming point (positions, diameters, forces), with its growth and largest
        displacement measured from the start of the path.
    swaps : tuple of Swap
        The pivots in order.
    seconds : float
        Wall time of the path.
    jammed : bool
        Every force is positive: the path reached a jamming point. False: the path stopped
        (why is returned beside it) at this vertex, no lower in Γ than its start.
    cost : Tally
        The sparse LU work of the path: factorisations and solves, with their wall time.
    """

    i: np.ndarray
    j: np.ndarray
    rattlers: np.ndarray
    refinement: Refinement
    swaps: tuple[Swap, ...]
    seconds: float
    jammed: bool = True
    cost: Tally = field(default_factory=Tally)

    @property
    def pivots(self) -> int:
        """Pivots taken."""
        return len(self.swaps)

    @property
    def factorizations(self) -> int:
        """Sparse LU factorisations made by the path (directions, Newton, rattlers)."""
        return self.cost.factorizations

    @property
    def degenerate(self) -> int:
        """Pivots that gained no inflation."""
        return sum(swap.growth <= DEGENERATE_STEP for swap in self.swaps)

    @property
    def median_pivot_seconds(self) -> float:
        """The median wall time of one pivot (nan without pivots)."""
        return float(np.median([swap.seconds for swap in self.swaps])) if self.swaps else np.nan

    @property
    def largest_growth(self) -> float:
        """The largest relative diameter growth of one pivot."""
        return max((swap.growth for swap in self.swaps), default=0.0)


@dataclass(frozen=True, eq=False)
class Vertex:
    """A point of the path: an isostatic network at its Newton point (diameters σ √Γ, so that
    Φ_c = |r_c|²/σ_c² − 1 vanishes on the contacts)."""

    i: np.ndarray
    j: np.ndarray
    stable: np.ndarray
    refinement: Refinement
    basis: Basis | None = None
    swapped: tuple[int, ...] = ()

    @property
    def keys(self) -> np.ndarray:
        return self.i * self.stable.shape[0] + self.j


class _SwappedFactors:
    """Solves with a matrix M that equals a factorised base matrix B but in k rows R, by the
    Woodbury identity: with W = B⁻¹ E_R (n × k) and V = M[R] − B[R] (k × n), S = I + V W,

        M⁻¹ b = y − W S⁻¹ V y  (y = B⁻¹ b),   M⁻ᵀ b = B⁻ᵀ (b − Vᵀ S⁻ᵀ Wᵀ b):

    one solve with the base factors and a k × k system per solve."""

    def __init__(self, base: Factors, columns: np.ndarray, changes: sp.csr_matrix,
                 small: tuple[np.ndarray, np.ndarray]):
        self._base, self._columns, self._changes, self._small = base, columns, changes, small

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        if trans == "T":
            weights = lu_solve(self._small, self._columns.T @ rhs, trans=1)
            return self._base.solve(rhs - self._changes.T @ weights, trans="T")
        solution = self._base.solve(rhs)
        return solution - self._columns @ lu_solve(self._small, self._changes @ solution)


class Basis:
    """One sparse LU of a network's Jacobian (unknowns of the stable set `stable`), reused by
    the pivots that follow: a pivot swaps one row, and `factors_for` solves with the swapped
    matrix by the Woodbury identity (`_SwappedFactors`). The columns B⁻¹ e_r are kept.

    The basis of a path is the Jacobian of one of its vertices: the floppy mode's matrix K
    (a row of the Jacobian replaced by Γ's) and the next vertices' Jacobians are swapped rows
    of it, and the motion between vertices is left to the refinement of each solve. A basis
    of K itself (`gamma_row`, when a release changed the unknowns) serves its own pivot
    only: K is ill-conditioned where the released force is weak, and so would be every
    update of it."""

    def __init__(self, factors: Factors, matrix: sp.spmatrix, stable: np.ndarray,
                 gamma_row: int | None = None):
        self.factors = factors
        self.matrix = sp.csr_matrix(matrix)
        self.stable = stable
        self.gamma_row = gamma_row
        self._columns: dict[int, np.ndarray] = {}

    def fits(self, stable: np.ndarray) -> bool:
        """Whether the unknowns are those of the basis (same stable particles)."""
        return bool(np.array_equal(self.stable, stable))

    def factors_for(self, matrix: sp.spmatrix, rows: tuple[int, ...]) -> Factors | None:
        """Factors of `matrix`, which differs from the basis in `rows` (and by the motion of
        the particles elsewhere: the factors are then those of a nearby matrix); None when
        there are more than `MAX_ROW_SWAPS` rows or the small system is singular."""
        if not rows:
            return self.factors
        if len(rows) > MAX_ROW_SWAPS:
            return None
        index = np.array(rows)
        for row in rows:
            if row not in self._columns:
                unit = np.zeros(self.matrix.shape[0])
                unit[row] = 1.0
                self._columns[row] = self.factors.solve(unit)
        columns = np.column_stack([self._columns[row] for row in rows])
        changes = sp.csr_matrix(matrix)[index] - self.matrix[index]
        small = np.eye(index.size) + changes @ columns
        if not np.all(np.isfinite(small)):
            return None
        # conditioned after scaling its rows (a row swapped for Γ's scales as the force
        # released, which is no loss of accuracy)
        scale = np.abs(small).max(axis=1, keepdims=True)
        if not np.all(scale > 0) or np.linalg.cond(small / scale) > MAX_SMALL_CONDITION:
            return None
        return _SwappedFactors(self.factors, columns, sp.csr_matrix(changes), lu_factor(small))


def describe_path(path: PivotPath) -> str:
    """One clause on a path for the run's notes: pivots, time and its sparse LU share,
    contacts swapped, the forces left non-positive along the way, largest growth of one
    pivot."""
    listed = ", ".join(f"{swap.released}->{swap.closed}" for swap in path.swaps[:LISTED_SWAPS])
    more = f" and {path.pivots - LISTED_SWAPS} more" if path.pivots > LISTED_SWAPS else ""
    degenerate = f" ({path.degenerate} degenerate)" if path.degenerate else ""
    if not path.pivots:
        return f"no contact pivot was needed ({path.seconds:.2f} s)"
    cost = path.cost
    trail = [swap.non_positive for swap in path.swaps]
    return (f"{path.pivots} contact pivot(s){degenerate} in {path.seconds:.2f} s "
            f"({cost.factorizations} sparse LU factorisation(s), {cost.factorize_seconds:.2f} s; "
            f"{cost.solves} solves, {cost.solve_seconds:.2f} s) "
            f"repaired the network's non-positive forces (released->closed: "
            f"{listed}{more}; non-positive forces after each pivot: at most {max(trail)}, "
            f"{trail[-1]} at the end; largest growth of one pivot sqrt(Gamma)-1 = "
            f"{path.largest_growth:.1e})")
