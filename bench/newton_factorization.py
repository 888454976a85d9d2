"""Benchmark of the sparse LU of the Newton stage's contact Jacobian, by method.

For every jammed result given (an isostatic packing, `calippso.load_result`), the Jacobian of
its contact equations is factorised by SuperLU with each of its column orderings and by MKL
PARDISO (when `pypardiso` is installed), and one solve is checked. Prints a table and, with
--json, writes its rows.

    python bench/newton_factorization.py jammed_d3.npz jammed_d4.npz --json lu.json

Columns: d, N, unknowns, method, seconds to factorise (best of --repeat), nonzeros of the
factors (SuperLU), largest residual of one solve relative to the right-hand side.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from scipy.sparse.linalg import splu

import calippso
from calippso.certification.newton import contact_jacobian
from calippso.certification.sparse_lu import factorize, pardiso_available

SUPERLU_ORDERINGS = ["COLAMD", "MMD_ATA", "MMD_AT_PLUS_A"]


def timed(factorise, repeat: int):
    """The factors of the best of `repeat` calls, and that call's seconds."""
    best, factors = np.inf, None
    for _ in range(repeat):
        began = time.perf_counter()
        factors = factorise()
        best = min(best, time.perf_counter() - began)
    return factors, best


def rows_of(path: Path, repeat: int) -> list[dict]:
    """One row per method for the jammed result in `path`."""
    result = calippso.load_result(path)
    packing = result.packing
    i, j = result.contacts.T
    jacobian = contact_jacobian(packing.positions, packing.diameters, packing.box, i, j,
                                ~result.rattlers)
    rhs = np.random.default_rng(0).standard_normal(jacobian.shape[0])
    methods = {f"superlu {name}": (lambda name=name: splu(jacobian, permc_spec=name))
               for name in SUPERLU_ORDERINGS}
    if pardiso_available():
        methods["pardiso"] = lambda: factorize(jacobian, "pardiso")
    rows = []
    for method, factorise in methods.items():
        factors, seconds = timed(factorise, repeat)
        residual = np.abs(jacobian @ factors.solve(rhs) - rhs).max() / np.abs(rhs).max()
        fill = int(factors.L.nnz + factors.U.nnz) if hasattr(factors, "L") else None
        rows.append({"input": str(path), "d": packing.d, "n": packing.n,
                     "unknowns": int(jacobian.shape[0]), "method": method,
                     "seconds": seconds, "fill": fill, "residual": float(residual)})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path, help="jammed .npz results")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    print(f"{'d':>2} {'N':>6} {'unknowns':>8} {'method':<22} {'seconds':>8} {'fill':>10} "
          f"{'residual':>9}")
    rows = []
    for path in args.results:
        for row in rows_of(path, args.repeat):
            rows.append(row)
            fill = "" if row["fill"] is None else f"{row['fill']:,}"
            print(f"{row['d']:2d} {row['n']:6d} {row['unknowns']:8d} {row['method']:<22} "
                  f"{row['seconds']:8.3f} {fill:>10} {row['residual']:9.1e}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
