"""Benchmark of the sparse LU of the Newton stage's contact Jacobian, by method.

For every jammed result given (an isostatic packing, `calippso.load_result`), the Jacobian of
its contact equations is factorised by SuperLU with each of its column orderings and by MKL
PARDISO (when `pypardiso` is installed), and one solve is checked. Prints a table and, with
--json, writes its rows.

    python bench/newton_factorization.py jammed_d3.npz jammed_d4.npz --json lu.json
    python bench/newton_factorization.py jammed_d3.npz --methods pardiso
    MKL_CBWR=OFF python bench/newton_factorization.py jammed_d3.npz --methods pardiso

Columns: d, N, unknowns, method, seconds to factorise (best of --repeat), nonzeros of the
factors (SuperLU), largest residual of one solve relative to the right-hand side, and
whether the solves of the --repeat factorisations were identical bit for bit. PARDISO runs
in MKL's reproducible mode unless `MKL_CBWR` is set (`MKL_CBWR=OFF` switches it off).
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from scipy.sparse.linalg import splu

import calippso
from calippso.certification.newton import contact_jacobian
from calippso.certification.sparse_lu import factorize, pardiso_available

SUPERLU_ORDERINGS = ["COLAMD", "MMD_ATA", "MMD_AT_PLUS_A"]


def timed(factorise, repeat: int, rhs: np.ndarray):
    """The factors of the best of `repeat` calls, that call's seconds, and whether every
    call's factors solve `rhs` bit for bit alike."""
    best, factors, solutions = np.inf, None, []
    for _ in range(repeat):
        began = time.perf_counter()
        factors = factorise()
        best = min(best, time.perf_counter() - began)
        solutions.append(np.array(factors.solve(rhs)))
    same = all(np.array_equal(solution, solutions[0]) for solution in solutions)
    return factors, best, same


def rows_of(path: Path, repeat: int, only: list[str] | None = None) -> list[dict]:
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
    if only:
        methods = {name: factorise for name, factorise in methods.items()
                   if name.split()[-1] in only}
    rows = []
    for method, factorise in methods.items():
        factors, seconds, same = timed(factorise, repeat, rhs)
        residual = np.abs(jacobian @ factors.solve(rhs) - rhs).max() / np.abs(rhs).max()
        fill = int(factors.L.nnz + factors.U.nnz) if hasattr(factors, "L") else None
        rows.append({"input": str(path), "d": packing.d, "n": packing.n,
                     "unknowns": int(jacobian.shape[0]), "method": method,
                     "seconds": seconds, "fill": fill, "residual": float(residual),
                     "repeats": same, "mkl_cbwr": os.environ.get("MKL_CBWR", "AUTO")})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", type=Path, help="jammed .npz results")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--methods", nargs="+", choices=[*SUPERLU_ORDERINGS, "pardiso"],
                        help="only these (default: every SuperLU ordering and PARDISO)")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    print(f"{'d':>2} {'N':>6} {'unknowns':>8} {'method':<22} {'seconds':>8} {'fill':>10} "
          f"{'residual':>9} {'repeats':>7}")
    rows = []
    for path in args.results:
        for row in rows_of(path, args.repeat, args.methods):
            rows.append(row)
            fill = "" if row["fill"] is None else f"{row['fill']:,}"
            print(f"{row['d']:2d} {row['n']:6d} {row['unknowns']:8d} {row['method']:<22} "
                  f"{row['seconds']:8.3f} {fill:>10} {row['residual']:9.1e} "
                  f"{'yes' if row['repeats'] else 'no':>7}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
