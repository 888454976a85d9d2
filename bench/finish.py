"""What the finish needs: the contact-pivot path with no pivot budget, from the networks that
`jam` hands to it. Prints one table row per input and start (and writes JSON).

Each input is a soft-sphere quench in d = 3 (`generators.soft_quench`, kept in --cache). Two
starts are read from it, as `jam` reads them:

- ``network-first``: network first's rounds on the hint's candidate
  (`calippso.certification.network_first.settle_candidate`), with no pivot budget: every
  path of contact pivots they start is counted (the columns add them up);
- ``interior-lp``: the network of the first LP without crossover (`jam(...,
  crossover="off", network_first="off")`), at its Newton point, from which
  `calippso.certification.pivots.pivot_to_jamming` runs with no pivot budget.

Either runs for at most --time-limit seconds of pivots. With --stale, a probe asks whether the sparse LU of the start's
Jacobian still solves the same network's Jacobian at the positions one pivot later (by
iterative refinement, and as a GMRES preconditioner): what a factorisation carried along
the path by low-rank updates would need. Run from the repository root (2 cores, the ``large`` extra):

    python bench/finish.py --inputs 8192:1e-7:2 16384:1e-7:2 --cache DIR --json finish.json

Columns: N, seed, quench pressure, start, non-positive forces at the start, pivots
(degenerate), how the path ended, its seconds, the median seconds of one pivot, sparse LU
factorisations and their seconds, solves and their seconds, the rest (geometry: neighbour
searches, ratio tests, rattlers), and the non-positive forces left at the end. A
network-first row that settles also prints how far the first path's start was from the
settled network (its contacts that left, the pairs that entered) against the distinct
contacts the paths released and how many of those they closed again.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as sla

import calippso
from calippso.certification import network_first
from calippso.certification.network_guess import candidate_networks, check_network_hint
from calippso.certification.newton import MIN_FORCE_RATIO, contact_jacobian
from calippso.certification.sparse_lu import factorize
from calippso.certification.pivots import pivot_to_jamming
from calippso.geometry.neighbors import NeighborSearch
from calippso.stages import newton_stage

#: Pivots allowed to a path: no budget but the time limit.
UNLIMITED = 10**9
#: Refinement steps and Krylov iterations of the stale-factor probe (--stale).
STALE_STEPS = 8
STALE_KRYLOV = 10
STARTS = ("network-first", "interior-lp")


class _Captured(Exception):
    """Raised by the stand-in for `pivot_to_jamming` once it holds the path's start."""

    def __init__(self, arguments: tuple, refined):
        super().__init__("start captured")
        self.arguments, self.refined = arguments, refined


def _capture(positions, diameters, box, i, j, rattlers, refined=None, **budget):
    raise _Captured((positions, diameters, box, i, j, rattlers), refined)


def quench(n: int, pressure: float, seed: int, cache: Path) -> tuple[calippso.Packing,
                                                                      np.ndarray]:
    """The d = 3 quench of N particles to `pressure`, and its overlap network, from `cache`
    when there."""
    path = cache / f"quench_d3_n{n}_p{pressure:g}_seed{seed}.npz"
    if not path.exists():
        import generators

        made = generators.soft_quench(generators.diameters.monodisperse(n), 3, seed=seed,
                                      target_pressure=pressure)
        cache.mkdir(parents=True, exist_ok=True)
        np.savez(path, positions=made.packing.positions, diameters=made.packing.diameters,
                 box=made.packing.box, contacts=made.contacts)
    with np.load(path) as stored:
        return calippso.read(path), stored["contacts"]


def read_start(packing: calippso.Packing, start: str = "interior-lp"):
    """The path's start (positions, diameters, box, i, j, rattlers) and its Newton solution,
    in mean diameters, after the first LP without crossover; (None, why) when `jam` hands
    no network to the pivots there."""
    saved = newton_stage.pivot_to_jamming, newton_stage.INTERIOR_PIVOTS
    newton_stage.pivot_to_jamming = _capture
    newton_stage.INTERIOR_PIVOTS = UNLIMITED   # whatever the number of non-positive forces
    try:
        result = calippso.jam(packing, crossover="off", network_first="off", max_iters=1)
        return None, f"no pivots after LP 1 ({result.stop_reason})"
    except _Captured as captured:
        return captured, ""
    finally:
        newton_stage.pivot_to_jamming, newton_stage.INTERIOR_PIVOTS = saved


def network_first_rounds(packing: calippso.Packing, hint: np.ndarray,
                         time_limit: float) -> dict:
    """Network first's rounds on the hint's candidate with no pivot budget: every path's
    figures, added up, and whether the rounds settled the network."""
    scale = packing.mean_diameter
    search = NeighborSearch(packing.positions / scale, packing.diameters / scale,
                            packing.box / scale)
    candidate = candidate_networks(search, packing.d, check_network_hint(hint, packing.n))[0]
    paths, refused, starts = [], [], []
    began = time.perf_counter()

    def unbudgeted(*arguments, refined=None, **budget):
        starts.append(_keys(arguments[3], arguments[4], packing.n))
        left = max(time_limit - (time.perf_counter() - began), 0.0)
        path, failure = pivot_to_jamming(*arguments, refined=refined, max_pivots=UNLIMITED,
                                         time_limit=left)
        forces = refined.forces
        start = int(np.count_nonzero(forces <= MIN_FORCE_RATIO * forces.max()))
        (paths if path is not None else refused).append((start, path, failure))
        return path, failure

    saved = network_first.pivot_to_jamming, network_first.STAGE_PIVOT_FACTORIZATIONS
    network_first.pivot_to_jamming = unbudgeted
    network_first.STAGE_PIVOT_FACTORIZATIONS = UNLIMITED
    try:
        settled, failure, _ = network_first.settle_candidate(search, candidate, packing.d)
    finally:
        network_first.pivot_to_jamming, network_first.STAGE_PIVOT_FACTORIZATIONS = saved
    row = {"seconds": time.perf_counter() - began, "paths": len(paths),
           "refused_starts": len(refused),
           "ended": "settled" if settled is not None else failure}
    if paths:
        swaps = [swap for _, path, _ in paths for swap in path.swaps]
        row.update(non_positive_start=paths[0][0], pivots=len(swaps),
                   degenerate=sum(path.degenerate for _, path, _ in paths),
                   median_pivot_seconds=float(np.median([swap.seconds for swap in swaps]))
                   if swaps else float("nan"),
                   factorizations=sum(path.cost.factorizations for _, path, _ in paths),
                   factorize_seconds=sum(path.cost.factorize_seconds for _, path, _ in paths),
                   solves=sum(path.cost.solves for _, path, _ in paths),
                   solve_seconds=sum(path.cost.solve_seconds for _, path, _ in paths),
                   path_endings=[failure or "jammed" for _, _, failure in paths],
                   non_positive_trail=[swap.non_positive for swap in swaps],
                   non_positive_end=swaps[-1].non_positive if swaps else paths[-1][0])
        row.update(_distance(starts[0], settled, swaps, packing.n))
    elif refused:
        row["non_positive_start"] = refused[0][0]
    return row


def _keys(i: np.ndarray, j: np.ndarray, n: int) -> np.ndarray:
    return np.asarray(i, dtype=np.int64) * n + np.asarray(j, dtype=np.int64)


def _distance(start: np.ndarray, settled, swaps, n: int) -> dict:
    """How far the first path's start network is from the settled one (contacts of the start
    that left, pairs that entered), against what the paths did: the distinct contacts they
    released, and how many of those were closed again later."""
    released = {pair[0] * n + pair[1] for pair in (swap.released for swap in swaps)}
    closed = {pair[0] * n + pair[1] for pair in (swap.closed for swap in swaps)}
    row = {"released_distinct": len(released), "released_then_closed": len(released & closed)}
    if settled is not None:
        end = _keys(settled.i, settled.j, n)
        row.update(left=int(np.setdiff1d(start, end).size),
                   entered=int(np.setdiff1d(end, start).size))
    return row


def stale_factors(captured) -> dict:
    """Whether the factors of the start's Jacobian solve the same network's Jacobian at the
    positions one pivot later (what an updated factorisation would need along the path).

    Returns the normwise backward error max|b − A x| / max(|A| |x| + |b|) of A x = b (b
    random) after `STALE_STEPS` steps of iterative refinement with the old factors, and
    after `STALE_KRYLOV` GMRES iterations preconditioned by them; and the largest relative
    change of a Jacobian entry."""
    positions, diameters, box, i, j, rattlers = captured.arguments
    first, _ = pivot_to_jamming(*captured.arguments, refined=captured.refined, max_pivots=1)
    if first is None or not first.pivots:
        return {}
    stable = ~rattlers
    before = contact_jacobian(captured.refined.positions, captured.refined.diameters, box,
                              i, j, stable).tocsr()
    after = contact_jacobian(first.refinement.positions, first.refinement.diameters, box,
                             i, j, stable).tocsr()
    factors = factorize(before, strict=False)
    rhs = np.random.default_rng(0).standard_normal(after.shape[0])

    def backward(solution: np.ndarray) -> float:
        scale = abs(after) @ np.abs(solution) + np.abs(rhs)
        return float(np.abs(rhs - after @ solution).max() / scale.max())

    solution = factors.solve(rhs)
    for _ in range(STALE_STEPS):
        solution = solution + factors.solve(rhs - after @ solution)
    preconditioner = sla.LinearOperator(after.shape, matvec=factors.solve)
    krylov, _ = sla.gmres(after, rhs, M=preconditioner, rtol=1e-30, atol=0.0,
                          restart=STALE_KRYLOV, maxiter=1)
    change = abs(after - before).max() / abs(before).max()
    return {"stale_refinement_error": backward(solution),
            "stale_krylov_error": backward(krylov), "jacobian_change": float(change)}


def run(n: int, pressure: float, seed: int, start: str, cache: Path,
        time_limit: float, stale: bool = False) -> dict:
    packing, hint = quench(n, pressure, seed, cache)
    row = {"n": n, "pressure": pressure, "seed": seed, "start": start}
    if start == "network-first":
        row.update(network_first_rounds(packing, hint, time_limit))
        return row
    clock = time.perf_counter()
    captured, why = read_start(packing)
    row["reading_seconds"] = time.perf_counter() - clock
    if captured is None:
        row["ended"] = why
        return row
    forces = captured.refined.forces
    if stale:
        row.update(stale_factors(captured))
    row["non_positive_start"] = int(np.count_nonzero(forces <= MIN_FORCE_RATIO * forces.max()))
    clock = time.perf_counter()
    path, failure = pivot_to_jamming(*captured.arguments, refined=captured.refined,
                                     max_pivots=UNLIMITED, time_limit=time_limit)
    row["seconds"] = time.perf_counter() - clock
    row["ended"] = failure or "jammed"
    if path is None:
        return row
    end_forces = path.refinement.forces
    row.update(pivots=path.pivots, degenerate=path.degenerate,
               rejoined=sum(swap.rejoined for swap in path.swaps),
               new_rattlers=sum(swap.new_rattlers for swap in path.swaps),
               median_pivot_seconds=path.median_pivot_seconds,
               factorizations=path.cost.factorizations,
               factorize_seconds=path.cost.factorize_seconds, solves=path.cost.solves,
               solve_seconds=path.cost.solve_seconds,
               non_positive_trail=[swap.non_positive for swap in path.swaps],
               non_positive_end=int(np.count_nonzero(
                   end_forces <= MIN_FORCE_RATIO * end_forces.max())))
    return row


def line(row: dict) -> str:
    head = f"{row['n']:6d} {row['seed']:4d} {row['pressure']:7.0e} {row['start']:>13}"
    if "pivots" not in row:
        return f"{head} {row.get('non_positive_start', '-'):>6}  {row['ended'][:60]}"
    rest = row["seconds"] - row["factorize_seconds"] - row["solve_seconds"]
    return (f"{head} {row['non_positive_start']:6d} {row['pivots']:5d} ({row['degenerate']:3d}) "
            f"{row['ended'][:28]:>28} {row['seconds']:8.1f} {row['median_pivot_seconds']:7.2f} "
            f"{row['factorizations']:4d} {row['factorize_seconds']:7.1f} {row['solves']:6d} "
            f"{row['solve_seconds']:7.1f} {rest:7.1f} {row['non_positive_end']:5d}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", nargs="+", default=["8192:1e-7:2"],
                        help="quenches as N:pressure:seed")
    parser.add_argument("--starts", nargs="+", choices=STARTS, default=list(STARTS))
    parser.add_argument("--time-limit", type=float, default=1800.0,
                        help="seconds each path may take")
    parser.add_argument("--cache", type=Path, default=Path("bench/.finish-inputs"),
                        help="folder for the quenches")
    parser.add_argument("--stale", action="store_true",
                        help="also probe whether the start's factors serve one pivot later")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    print(f"{'N':>6} {'seed':>4} {'p':>7} {'start':>13} {'neg':>6} {'pivots (deg)':>12} "
          f"{'ended':>28} {'path s':>8} {'s/pivot':>7} {'LUs':>4} {'LU s':>7} {'solves':>6} "
          f"{'solve s':>7} {'other s':>7} {'neg end':>5}")
    rows = []
    for spec in args.inputs:
        n, pressure, seed = spec.split(":")
        for start in args.starts:
            row = run(int(n), float(pressure), int(seed), start, args.cache, args.time_limit,
                      args.stale)
            rows.append(row)
            print(line(row), flush=True)
            if "released_distinct" in row:
                print(f"{'':>32} start to end: {row.get('left', '-')} contacts left, "
                      f"{row.get('entered', '-')} entered; the paths released "
                      f"{row['released_distinct']} distinct contacts, "
                      f"{row['released_then_closed']} of them closed again", flush=True)
            if "stale_refinement_error" in row:
                print(f"{'':>32} stale factors one pivot later: Jacobian entries change by "
                      f"{row['jacobian_change']:.1e} (relative); backward error after "
                      f"{STALE_STEPS} refinement steps {row['stale_refinement_error']:.1e}, "
                      f"after {STALE_KRYLOV} GMRES iterations {row['stale_krylov_error']:.1e}",
                      flush=True)
            if args.json:
                args.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
