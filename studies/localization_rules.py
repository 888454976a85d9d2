"""Force exponents of an ensemble under each localisation rule, and the opening-response cost.

For every jammed result given (.npz/.h5, pooled), the script classifies the contacts with the
rules "bucklers" (every force on a buckler), "weakest" (each buckler's weakest force) and
"response" at several thresholds (contacts whose opening response puts more than that share of
its squared displacement on one particle; docs/analysis.md, Definitions), then fits θ_ℓ and θ_e
with the default windows and models (1000 bootstrap resamples of the packings, seed 0). It
prints the time of the opening response per packing (with ``--sparse``, also the time with
SuperLU instead of the dense LAPACK factorisation), the shares by class of contact, and one
row per rule. Run from the repository root:

    python studies/localization_rules.py folder/*.npz
    python studies/localization_rules.py folder/*.npz --thresholds 0.5 --sparse
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from calippso.analysis.exponents import exponent_from_sample
from calippso.analysis.forces import (RESPONSE_THRESHOLD, bucklers, localized_contacts,
                                      normalized_forces)
from calippso.analysis.response import opening_response
from calippso.analysis.sample import PooledSample
from calippso.io import read_result


def _pooled(parts: list[np.ndarray]) -> PooledSample:
    return PooledSample.concatenate([(part, part.size) for part in parts])


def _times(times: list[float]) -> str:
    return f"{np.median(times):.2f} (median; {min(times):.2f}-{max(times):.2f})"


def _exponent(name: str, parts: list[np.ndarray], n_bootstrap: int) -> str:
    try:
        e = exponent_from_sample(name, _pooled(parts), n_bootstrap=n_bootstrap, seed=0)
    except ValueError as error:
        return f"({error})"
    return f"{e.value:.3f} [{e.interval[0]:.3f}, {e.interval[1]:.3f}] {e.fit.model}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", nargs="+", help="jammed results (.npz or .h5), pooled")
    parser.add_argument("--thresholds", type=float, nargs="+",
                        default=[0.3, RESPONSE_THRESHOLD, 0.7])
    parser.add_argument("--bootstrap", type=int, default=1000)
    parser.add_argument("--sparse", action="store_true",
                        help="also time the response with the sparse (SuperLU) factorisation")
    args = parser.parse_args()

    results = [read_result(path) for path in args.results]
    forces = [normalized_forces(r) for r in results]
    masks: dict[str, list[np.ndarray]] = {rule: [localized_contacts(r, rule) for r in results]
                                          for rule in ("bucklers", "weakest")}
    times, responses = [], []
    for result in results:
        start = time.perf_counter()
        responses.append(opening_response(result))
        times.append(time.perf_counter() - start)
    for threshold in args.thresholds:
        masks[f"response > {threshold:g}"] = [resp.localized(threshold) for resp in responses]

    n = results[0].packing.n
    print(f"{len(results)} packings, d = {results[0].d}, N = {n}; opening response "
          f"{_times(times)} s per packing")
    rcond = [resp.reciprocal_condition for resp in responses]
    print(f"reciprocal condition number of the opening equations: {min(rcond):.1e} to "
          f"{max(rcond):.1e} (refused below unknowns x machine epsilon, about 1e-12)")
    if args.sparse:
        sparse_times = []
        for result in results:
            start = time.perf_counter()
            opening_response(result, factorization="sparse")
            sparse_times.append(time.perf_counter() - start)
        print(f"with SuperLU instead: {_times(sparse_times)} s per packing")
    print("\nshare of the opening response on the particle that moves most, by class of contact")
    print("| contacts | count | median share | share > 0.5 |")
    print("|---|---|---|---|")
    weakest, on_buckler = masks["weakest"], masks["bucklers"]
    classes = {"weakest contact of a buckler": weakest,
               "other contacts of bucklers": [b & ~w for b, w in zip(on_buckler, weakest)],
               "no buckler at either end": [~b for b in on_buckler]}
    for label, chosen in classes.items():
        share = np.concatenate([resp.share[m] for resp, m in zip(responses, chosen)])
        print(f"| {label} | {share.size} | {np.median(share):.3f} | {np.mean(share > 0.5):.3f} |")
    movers = np.concatenate([bucklers(r)[resp.mover[resp.localized()]]
                             for r, resp in zip(results, responses)])
    print(f"localised responses (share > 0.5) that move a buckler: {movers.mean():.3f} "
          f"of {movers.size}")

    print("\n| rule | localised | extended | θ_ℓ | θ_e |")
    print("|---|---|---|---|---|")
    for rule, rule_masks in masks.items():
        local = [f[m] for f, m in zip(forces, rule_masks)]
        extended = [f[~m] for f, m in zip(forces, rule_masks)]
        print(f"| {rule} | {sum(p.size for p in local)} | {sum(p.size for p in extended)} | "
              f"{_exponent('theta_l', local, args.bootstrap)} | "
              f"{_exponent('theta_e', extended, args.bootstrap)} |")


if __name__ == "__main__":
    main()
