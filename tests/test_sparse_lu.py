"""Sparse LU of contact Jacobians: SuperLU and PARDISO give the same solutions, in both
directions, and both report a singular matrix as None."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp

from calippso.certification import sparse_lu
from calippso.certification.sparse_lu import factorize, pardiso_available

METHODS = ["superlu", pytest.param("pardiso", marks=pytest.mark.skipif(
    not pardiso_available(), reason="pypardiso (the pardiso extra) is not installed"))]


def nonsymmetric(n: int, seed: int) -> sp.csc_matrix:
    """A well-conditioned random sparse nonsymmetric matrix, shape (n, n)."""
    random = sp.random(n, n, density=5.0 / n, random_state=seed, format="csc")
    return (random + 4.0 * sp.eye(n)).tocsc()


@pytest.mark.parametrize("method", METHODS)
def test_solves_and_transposed_solves(method):
    matrix = nonsymmetric(500, seed=1)
    rhs = np.random.default_rng(2).standard_normal(500)
    factors = factorize(matrix, method)
    for trans, operator in (("N", matrix), ("T", matrix.T)):
        solution = factors.solve(rhs, trans=trans)
        assert np.abs(operator @ solution - rhs).max() < 1e-12


@pytest.mark.parametrize("method", METHODS)
def test_a_singular_matrix_gives_none(method):
    dense = np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]])
    assert factorize(sp.csc_matrix(dense), method) is None


@pytest.mark.parametrize("method", METHODS)
def test_factors_stay_valid_after_another_factorisation(method):
    """PARDISO keeps one factorisation per process: older factors must still solve right."""
    first, second = nonsymmetric(300, seed=3), nonsymmetric(300, seed=4)
    rhs = np.ones(300)
    old = factorize(first, method)
    factorize(second, method)
    assert np.abs(first @ old.solve(rhs) - rhs).max() < 1e-12


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="unknown factorisation 'umfpack'"):
        factorize(sp.eye(3, format="csc"), "umfpack")


@pytest.mark.skipif(not pardiso_available(), reason="pypardiso (the pardiso extra) is not installed")
def test_pardiso_runs_in_mkl_reproducible_mode_and_repeats_bit_for_bit(monkeypatch):
    """PARDISO on several threads varies in the last bits from run to run unless MKL's
    conditional numerical reproducibility is on; the solver turns it on."""
    script = (
        "import numpy as np, scipy.sparse as sp\n"
        "from calippso.certification import sparse_lu\n"
        "rng = np.random.default_rng(0)\n"
        "m = (sp.random(3000, 3000, density=2e-3, random_state=1) + 10 * sp.identity(3000))\n"
        "x = sparse_lu.factorize(m.tocsc(), method='pardiso').solve(rng.uniform(size=3000))\n"
        "lib = sparse_lu._pardiso_solver().libmkl\n"
        "print(lib.MKL_CBWR_Get(-1), x.tobytes().hex()[:64], np.abs(m @ x).sum())\n")
    monkeypatch.delenv("MKL_CBWR", raising=False)
    runs = [subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                           check=True).stdout.split() for _ in range(2)]
    assert int(runs[0][0]) == sparse_lu.MKL_CBWR_AUTO
    assert runs[0] == runs[1]


def test_factors_solve_without_factorising_again():
    """Each PARDISO factorisation has a handle of its own: solving with older factors after
    another factorisation is a solve (phase 33), not a new factorisation (phase 13)."""
    if not pardiso_available():
        pytest.skip("pypardiso (the pardiso extra) is not installed")
    first, second = nonsymmetric(300, seed=3), nonsymmetric(300, seed=4)
    old = factorize(first, "pardiso")
    factorize(second, "pardiso")
    for trans in ("N", "T"):
        old.solve(np.ones(300), trans=trans)
        assert old._factors._solver.phase == 33


@pytest.mark.parametrize("method", METHODS)
def test_a_tally_counts_factorisations_and_solves(method):
    matrix = nonsymmetric(200, seed=5)
    with sparse_lu.tally() as outer:
        factors = factorize(matrix, method)
        with sparse_lu.tally() as inner:
            factors.solve(np.ones(200))
            factors.solve(np.ones(200), trans="T")
    factors.solve(np.ones(200))   # after both closed: not counted
    assert (outer.factorizations, outer.solves) == (1, 2)
    assert (inner.factorizations, inner.solves) == (0, 2)
    assert outer.factorize_seconds > 0 and outer.solve_seconds >= inner.solve_seconds > 0
