"""Time of the analysis and of the report on many large packings, and on several sizes.

Reads certified results (``--inputs DIR ...``: folders or files, e.g. the folders that
``bench/size_ensembles.py`` writes), repeats each one ``--tile K`` times along every axis of
its periodic box (K^d N particles with the contacts and forces of the input in every copy:
touching, positive and balanced as the input's, though K^d − 1 rigid translations of the
copies against each other take the isostatic count off by (K^d − 1)(d − 1)), and takes
``--packings`` of them (the inputs cycled when there are fewer). Then it times, on one process:

* ``analysis``: `calippso.analysis.analyze` of the tiled packings (pooled fits with 1000
  resamples, the window check);
* ``report``: `calippso.report` of them into a temporary folder (figures, one history per
  run);
* ``report, two sizes``: `calippso.report` of the tiled packings with the packings of
  ``--second-size`` (by default the inputs themselves, when they are tiled): the per-size
  fits, the extrapolation and the figures across sizes.

Run alone on the machine, on tiled packings or on packings of the size itself::

    python bench/finite_size_analysis.py --inputs DIR/d3_n1024 \\
        --tile 2 --packings 50 --json rows.json
    python bench/finite_size_analysis.py --inputs DIR/d3_n8192 --tile 1 \\
        --packings 50 --second-size DIR/d3_n1024

Prints one row per case (packings, N, seconds) and writes them to ``--json``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import calippso
from calippso.result import JammingResult


def tiled_result(result: JammingResult, k: int) -> JammingResult:
    """`result` repeated `k` times along every axis of its periodic box.

    Copy c of particle i sits at r_i + c L. A contact (i, j) whose minimum image is
    r_j − s L joins copy c of i with copy (c − s) mod k of j, so every copy holds the
    contacts and forces of the input.
    """
    packing = result.packing
    if k == 1:
        return result
    if not packing.boundaries.is_periodic:
        raise SystemExit("--tile needs periodic packings")
    d, n = packing.d, packing.n
    box = np.broadcast_to(np.asarray(packing.box, dtype=np.float64), (d,))
    cells = np.stack(np.meshgrid(*[np.arange(k)] * d, indexing="ij"), -1).reshape(-1, d)
    positions = (packing.positions[None] + cells[:, None] * box).reshape(-1, d)
    i, j = result.contacts[:, 0], result.contacts[:, 1]
    shift = np.rint((packing.positions[j] - packing.positions[i]) / box).astype(np.int64)
    weights = k ** np.arange(d - 1, -1, -1)          # cell index of the meshgrid order
    pairs = []
    for c, cell in enumerate(cells):
        partner = ((cell[None] - shift) % k) @ weights
        pairs.append(np.c_[i + c * n, j + partner * n])
    pairs = np.sort(np.concatenate(pairs), axis=1)
    copies = cells.shape[0]
    tiled = calippso.Packing(positions, np.tile(packing.diameters, copies), box * k)
    return replace(result, packing=tiled, contacts=pairs,
                   forces=np.tile(result.forces, copies),
                   rattlers=np.tile(result.rattlers, copies))


def read_inputs(paths: list[Path]) -> list[JammingResult]:
    """The results in the files and folders given (``packing_*.npz`` in a folder)."""
    results = []
    for path in paths:
        files = sorted(path.glob("packing_*.npz")) if path.is_dir() else [path]
        results += [calippso.load_result(f) for f in files]
    if not results:
        raise SystemExit("no result in --inputs")
    return results


def timed(call) -> float:
    """Wall seconds of `call()`."""
    clock = time.perf_counter()
    call()
    return time.perf_counter() - clock


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", type=Path, nargs="+", required=True)
    parser.add_argument("--tile", type=int, default=2)
    parser.add_argument("--packings", type=int, default=50)
    parser.add_argument("--second-size", type=Path, nargs="+", default=None,
                        help="results of another size for the two-size report (default: "
                             "the inputs, when --tile is above 1)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    inputs = read_inputs(args.inputs)
    second = (read_inputs(args.second_size) if args.second_size is not None
              else inputs if args.tile > 1 else [])
    large = [tiled_result(r, args.tile) for r in itertools.islice(itertools.cycle(inputs),
                                                                   args.packings)]
    n_large = sorted({r.packing.n for r in large})
    n_small = sorted({r.packing.n for r in second})
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        cases = [("analysis", large, n_large,
                  lambda: calippso.analysis.analyze(large)),
                 ("report", large, n_large,
                  lambda: calippso.report(large, Path(folder) / "large")),
                 ("report, two sizes", large + second, n_small + n_large,
                  lambda: calippso.report(large + second, Path(folder) / "sizes"))]
        if not second:   # packings of one size only
            cases = cases[:2]
        print("| case | packings | N | distinct inputs | s |")
        print("|---|---|---|---|---|")
        for name, results, sizes, call in cases:
            seconds = timed(call)
            row = {"case": name, "packings": len(results), "n": sizes,
                   "distinct_inputs": len(inputs), "tile": args.tile, "seconds": seconds}
            rows.append(row)
            print(f"| {name} | {len(results)} | {', '.join(map(str, sizes))} | "
                  f"{len(inputs)} | {seconds:.1f} |", flush=True)
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
