"""Sparse LU factorisation of the contact Jacobian, for the Newton stage.

Two implementations behind one interface (`factorize`, then ``solve(b)`` and
``solve(b, trans="T")`` with the same factors):

- scipy's SuperLU with the COLAMD column ordering: always available; the least fill of
  SuperLU's orderings on contact Jacobians, and the fastest for small systems;
- Intel MKL PARDISO through `pypardiso` (the ``pardiso`` extra, x86-64 Linux and Windows):
  nested-dissection ordering and threads; it fills in far less on large networks and takes
  over from `PARDISO_MIN_UNKNOWNS` unknowns when it is installed.

`bench/newton_factorization.py` measures both on jammed packings.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import os
import sys
import time
import weakref
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..c_stdout import c_stdout_to_stderr

__all__ = ["Factors", "factorize", "pardiso_available", "PARDISO_MIN_UNKNOWNS", "MKL_CBWR_AUTO",
           "Tally", "tally"]

#: PARDISO is used from this many unknowns on (when installed): from a d = 3, N = 1024
#: network (~3000 unknowns) on it factorises faster than SuperLU, by more the larger the
#: network; on small networks both take milliseconds, and SuperLU needs no MKL.
PARDISO_MIN_UNKNOWNS = 2500
#: MKL's conditional numerical reproducibility mode `MKL_CBWR_AUTO` (mkl_cbwr.h). PARDISO on
#: several threads otherwise varies in the last bits from run to run, which can change the
#: path of network first; in this mode its results repeat bit for bit on a fixed number of
#: threads. An `MKL_CBWR` set in the environment is left to take effect instead.
MKL_CBWR_AUTO = 2


class Factors(Protocol):
    """Factors of a square matrix A."""

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        """A⁻¹ rhs (``trans="N"``) or A⁻ᵀ rhs (``trans="T"``), shape (n,)."""


@dataclass
class Tally:
    """Sparse LU work counted while a `tally` is open.

    Attributes
    ----------
    factorizations : int
        Matrices factorised (singular ones included).
    factorize_seconds : float
        Wall time of those factorisations.
    solves : int
        Solves with any factors (each refinement step is one).
    solve_seconds : float
        Wall time of those solves.
    """

    factorizations: int = 0
    factorize_seconds: float = 0.0
    solves: int = 0
    solve_seconds: float = 0.0


#: The open tallies, innermost last (`tally`).
_OPEN_TALLIES: list[Tally] = []


@contextlib.contextmanager
def tally() -> Iterator[Tally]:
    """Count the factorisations and solves made inside the block, with their wall time.

    Every solve inside the block counts, whenever its factors were made (nested tallies
    each see the work of their own blocks).
    """
    counted = Tally()
    _OPEN_TALLIES.append(counted)
    try:
        yield counted
    finally:
        _OPEN_TALLIES.remove(counted)


class _TalliedFactors:
    """Factors whose solves are counted by the tallies open at the time (`tally`)."""

    def __init__(self, factors: Factors):
        self._factors = factors

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        began = time.perf_counter()
        solution = self._factors.solve(rhs, trans)
        elapsed = time.perf_counter() - began
        for counted in _OPEN_TALLIES:
            counted.solves += 1
            counted.solve_seconds += elapsed
        return solution


def pardiso_available() -> bool:
    """Whether `pypardiso` (MKL PARDISO) is installed (checked without importing it)."""
    return importlib.util.find_spec("pypardiso") is not None


@functools.lru_cache(maxsize=1)
def _pardiso_solver():
    """The first PARDISO solver of this process; making it sets up MKL once: the runtime's
    path, and MKL's reproducible mode (`MKL_CBWR_AUTO`).

    pypardiso looks for the MKL runtime by a recursive search of the whole Python prefix,
    which takes seconds in a large environment; where pip puts it (the prefix's `lib`, or
    `Library/bin` on Windows) it is found directly and handed over by PYPARDISO_MKL_RT.
    """
    if "PYPARDISO_MKL_RT" not in os.environ:
        prefix = Path(sys.prefix)
        found = sorted(prefix.glob("lib/libmkl_rt.so*")) + sorted(
            prefix.glob("Library/bin/mkl_rt*.dll"))
        if found:
            os.environ["PYPARDISO_MKL_RT"] = str(found[0])
    import pypardiso

    solver = pypardiso.PyPardisoSolver(mtype=11)
    if "MKL_CBWR" not in os.environ:   # set before MKL computes anything
        solver.libmkl.MKL_CBWR_Set(MKL_CBWR_AUTO)
    return solver


def _new_pardiso_solver():
    """A PARDISO solver with a handle of its own (its own factors), MKL set up as
    `_pardiso_solver` does."""
    import pypardiso

    _pardiso_solver()
    return pypardiso.PyPardisoSolver(mtype=11)


def factorize(matrix: sp.spmatrix, method: str = "auto", strict: bool = True) -> Factors | None:
    """LU factors of a square sparse matrix, or None when it is singular.

    Parameters
    ----------
    matrix : sparse matrix, shape (n, n), float64
    method : {"auto", "superlu", "pardiso"}
        "auto": PARDISO from `PARDISO_MIN_UNKNOWNS` unknowns on when `pypardiso` is
        installed, SuperLU otherwise.
    strict : bool
        Refuse PARDISO factors with perturbed pivots whose test solve is inaccurate (they
        may belong to a singular matrix). With False they are kept: the caller refines its
        solves against the matrix and judges them by their residuals (a non-singular
        matrix then solves to round-off, a singular one does not).
    """
    if method not in ("auto", "superlu", "pardiso"):
        raise ValueError(f"unknown factorisation {method!r}: choose auto, superlu or pardiso")
    began = time.perf_counter()
    factors = _factorize(matrix, method, strict)
    elapsed = time.perf_counter() - began
    for counted in _OPEN_TALLIES:
        counted.factorizations += 1
        counted.factorize_seconds += elapsed
    return None if factors is None else _TalliedFactors(factors)


def _factorize(matrix: sp.spmatrix, method: str, strict: bool) -> Factors | None:
    """`factorize` without the tally."""
    use_pardiso = method == "pardiso" or (
        method == "auto" and matrix.shape[0] >= PARDISO_MIN_UNKNOWNS and pardiso_available())
    if use_pardiso:
        return _PardisoFactors.of(matrix, strict)
    try:
        with c_stdout_to_stderr():   # BLAS's complaints on a singular matrix (c_stdout)
            return splu(sp.csc_matrix(matrix), permc_spec="COLAMD")
    except RuntimeError:  # exactly or numerically singular
        return None


class _PardisoFactors:
    """MKL PARDISO factors of a real nonsymmetric matrix (`pypardiso`).

    The matrix is held in CSR form; a CSC matrix on the same three arrays is its transpose,
    which pypardiso solves with the stored factors (PARDISO's transposed solve). Each set of
    factors has a PARDISO handle of its own, released with it: factors kept for later
    solves (the bases of `calippso.certification.pivots`) stay valid while other matrices
    are factorised.
    """

    #: PARDISO's output parameter (1-based) counting perturbed pivots. PARDISO pivots
    #: statically, so a perturbed pivot may mean a singular matrix or only an unlucky order;
    #: the factors are kept when a test solve leaves a relative residual below
    #: `PERTURBED_RESIDUAL`.
    PERTURBED_RESIDUAL = 1e-10
    PERTURBED_PIVOTS = 14

    def __init__(self, solver, matrix: sp.csr_matrix):
        self._solver = solver
        # PARDISO's memory of this handle goes with the factors (the process's end frees it)
        weakref.finalize(self, solver.free_memory, True).atexit = False
        self._matrix = matrix
        self._transposed = sp.csc_matrix((matrix.data, matrix.indices, matrix.indptr),
                                         shape=matrix.shape)

    @classmethod
    def of(cls, matrix: sp.spmatrix, strict: bool = True) -> "_PardisoFactors | None":
        csr = sp.csr_matrix(matrix, dtype=np.float64)
        csr.sort_indices()
        if not np.diff(csr.indptr).all() or not np.diff(csr.tocsc().indptr).all():
            return None   # an empty row or column: singular (and PARDISO would crash)
        solver = _new_pardiso_solver()
        solver.factorize(csr)
        factors = cls(solver, csr)
        if strict and solver.get_iparm(cls.PERTURBED_PIVOTS) > 0 and not factors._accurate():
            return None   # its handle is released with it
        return factors

    def _accurate(self) -> bool:
        """Whether a solve with a random right-hand side b (outside the range of a singular
        matrix, almost surely) leaves a residual below `PERTURBED_RESIDUAL` × |b|: a
        perturbed singular pivot leaves one of order |b|."""
        target = np.random.default_rng(0).uniform(1.0, 2.0, self._matrix.shape[0])
        solution = self.solve(target)
        if not np.all(np.isfinite(solution)):
            return False
        residual = np.abs(self._matrix @ solution - target).max()
        return bool(residual <= self.PERTURBED_RESIDUAL * target.max())

    def solve(self, rhs: np.ndarray, trans: str = "N") -> np.ndarray:
        matrix = self._transposed if trans == "T" else self._matrix
        return np.asarray(self._solver.solve(matrix, np.asarray(rhs, dtype=np.float64)))
