"""Standard output carries only what a command promises, whatever compiled code prints.

SuperLU, on a numerically singular matrix, reaches the BLAS error handler, which prints "On
entry to DGEMV parameter number 2 had an illegal value" to file descriptor 1 (past
`sys.stdout`). `calippso.certification.sparse_lu.factorize` sends it to standard error and reports the
matrix as singular; ``calippso jam --json`` output therefore stays valid JSON.
"""

from __future__ import annotations

import json
import os

import pytest
import scipy.sparse as sp

import calippso
from calippso.c_stdout import c_stdout_to_devnull, c_stdout_to_stderr
from calippso.certification.sparse_lu import factorize
from configurations import overlap_free
from conftest import OVERLAP_TOLERANCE

#: A sparse matrix of this size and seed, its first `DEPENDENT` columns sums of two others,
#: reaches the BLAS error handler inside SuperLU (found by a scan of seeds).
SIZE, SEED, DEPENDENT = 300, 43, 5


def numerically_singular() -> sp.csc_matrix:
    """A sparse (SIZE, SIZE) matrix with explicit zeros on its diagonal (as an assembled
    Jacobian may hold) and dependent columns: singular, and SuperLU meets it with BLAS calls
    whose arguments BLAS rejects."""
    matrix = sp.random(SIZE, SIZE, density=0.02, random_state=SEED, format="lil")
    matrix.setdiag(0)
    for column in range(DEPENDENT):
        matrix[:, column] = matrix[:, column + 100] + matrix[:, column + 200]
    return matrix.tocsc()


def test_a_singular_factorisation_prints_nothing_on_stdout(capfd):
    assert factorize(numerically_singular(), method="superlu") is None
    out, err = capfd.readouterr()
    assert out == ""
    assert "illegal value" in err      # the input does reach the BLAS error handler


def test_guards_restore_descriptor_1(capfd):
    with c_stdout_to_devnull():
        os.write(1, b"dropped\n")      # as compiled code writes: to the descriptor
    with c_stdout_to_stderr():
        os.write(1, b"to stderr\n")
    os.write(1, b"kept\n")
    out, err = capfd.readouterr()
    assert out == "kept\n"
    assert err == "to stderr\n"


def _degenerate(case: str, request):
    import lattices

    if case == "square":
        return lattices.square(8, 0.98)
    if case == "bcc":
        return lattices.bcc(4, 0.98)
    if case == "crystal-discs":
        return lattices.triangular(6, 0.98)
    # equal discs quenched: they crystallise in patches, and jam ends NOT_RIGID
    return request.getfixturevalue("quenched_discs").packing


@pytest.mark.parametrize("case", ["square", "bcc", "crystal-discs", "quenched-discs"])
def test_jam_json_parses_on_degenerate_inputs(case, tmp_path, capfd, request):
    """Degenerate inputs (lattices that are not jammed, discs that crystallise): the --json
    output is one JSON document, whatever the LPs and factorisations met."""
    from calippso import write
    from calippso.cli import main

    start = _degenerate(case, request)
    path = tmp_path / "start.npz"
    write(start, path)
    main(["jam", str(path), "-o", str(tmp_path / "jammed.npz"), "--json", "--quiet"])
    out, _ = capfd.readouterr()
    record = json.loads(out)
    assert record["n"] == start.n
    # the record says what the run proved: "Jammed" exactly when converged, and a converged
    # packing overlaps nowhere
    assert record["converged"] == record["status"].startswith("Jammed")
    if record["converged"]:
        result = calippso.load_result(tmp_path / "jammed.npz")
        assert overlap_free(result.packing) >= -OVERLAP_TOLERANCE
