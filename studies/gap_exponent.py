"""γ of jammed LS packings: stable pairs against all pairs, and the input pressure.

For every seed and pressure it makes an LS packing (N = 1024, d = 3, growth rate 1e-2),
jams it with the default `calippso.jam` settings, and pools the gaps h = |r|/σ − 1 in a
fixed window [1e-6, 1e-2]. Run from the repository root:

    python studies/gap_exponent.py --keep /tmp/gap-exponent            # seeds 2-21, p = 1e5, 1e12
    python studies/gap_exponent.py --seeds 2 3 4 --pressures 1e5

Printed per pressure: mean φ_J; γ over pairs of stable particles (the definition of
`calippso.analysis`) and over all pairs, rattlers included, each a maximum-likelihood fit
with a 95 % interval from resampling whole packings; then, for the rattlers, how many of
their gaps lie below 1e-4, 1e-6 and 1e-9. For the highest pressure it also counts the
pairs of the LS state itself with h < 1e-6 against the contacts after jamming; with
several pressures, the largest difference of φ_J between pressures for one seed.
`--keep DIR` stores the LS states and the jam results and reads them back on the next run.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

import calippso
from calippso.analysis import gaps as stable_gaps
from calippso.analysis.fits import window_mle
from calippso.geometry.neighbors import NeighborSearch

WINDOW = (1e-6, 1e-2)
RESAMPLES = 300


def ls_state(seed: int, pressure: float, keep: Path | None) -> calippso.Packing:
    """The LS packing of one seed at one pressure (read from `keep` when stored there)."""
    path = keep / f"ls_p{pressure:g}_s{seed}.npz" if keep else None
    if path is not None and path.exists():
        return calippso.read(path)
    import generators

    packing = generators.lubachevsky_stillinger(np.ones(1024), d=3, target_pressure=pressure,
                                                seed=seed, growth_rate=1e-2).packing
    if path is not None:
        np.savez(path, positions=packing.positions, diameters=packing.diameters,
                 box=packing.box)
    return packing


def jammed(seed: int, pressure: float, keep: Path | None) -> calippso.JammingResult:
    """`calippso.jam` of that LS packing (read from `keep` when stored there)."""
    path = keep / f"jam_p{pressure:g}_s{seed}.npz" if keep else None
    if path is not None and path.exists():
        return calippso.load_result(path)
    result = calippso.jam(ls_state(seed, pressure, keep))
    if not result.isostatic:
        raise RuntimeError(f"seed {seed}, p = {pressure:g}: {result.status}")
    if path is not None:
        result.save(path)
    return result


def all_pair_gaps(packing: calippso.Packing) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gaps of all pairs within 1.02 × the largest diameter, with their two particles."""
    search = NeighborSearch(packing.positions, packing.diameters, packing.box)
    pairs = search.pairs_within(1.02 * float(packing.diameters.max()))
    return pairs.gaps, pairs.i, pairs.j


def in_window(h: np.ndarray) -> np.ndarray:
    return h[(h >= WINDOW[0]) & (h <= WINDOW[1])]


def gamma_with_interval(per_packing: list[np.ndarray]) -> str:
    """γ = 1 − α of the pooled gaps, with the 2.5–97.5 % range over resampled packings."""
    def gamma(groups):
        return 1.0 - window_mle(np.concatenate(groups), *WINDOW)

    rng = np.random.default_rng(0)
    resampled = [gamma([per_packing[k] for k in rng.integers(0, len(per_packing),
                                                             len(per_packing))])
                 for _ in range(RESAMPLES)]
    low, high = np.percentile(resampled, [2.5, 97.5])
    count = sum(group.size for group in per_packing)
    return f"{gamma(per_packing):.3f} [{low:.3f}, {high:.3f}] ({count} gaps)"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(2, 22)))
    parser.add_argument("--pressures", type=float, nargs="+", default=[1e5, 1e12])
    parser.add_argument("--keep", type=Path, help="folder to store and reuse packings")
    args = parser.parse_args()
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)

    phi = {}
    for pressure in args.pressures:
        results = [jammed(seed, pressure, args.keep) for seed in args.seeds]
        phi[pressure] = np.array([r.packing.phi for r in results])
        stable = [in_window(stable_gaps(r)) for r in results]
        everything, rattler_gaps = [], []
        for r in results:
            h, i, j = all_pair_gaps(r.packing)
            everything.append(in_window(h))
            rattler_gaps.append(h[(r.rattlers[i] | r.rattlers[j]) & (h <= WINDOW[1])])
        rattler_gaps = np.concatenate(rattler_gaps)
        print(f"p = {pressure:g}, {len(results)} packings, phi_J {phi[pressure].mean():.5f}")
        print(f"  gamma, stable pairs: {gamma_with_interval(stable)}")
        print(f"  gamma, all pairs:    {gamma_with_interval(everything)}")
        print(f"  rattlers {sum(int(r.rattlers.sum()) for r in results)}: "
              f"{rattler_gaps.size} gaps h <= {WINDOW[1]:g}, "
              + ", ".join(f"{np.count_nonzero(rattler_gaps < x)} below {x:g}"
                          for x in (1e-4, 1e-6, 1e-9)))
    top = max(args.pressures)
    close = [np.count_nonzero(all_pair_gaps(ls_state(seed, top, args.keep))[0] < WINDOW[0])
             for seed in args.seeds]
    contacts = [jammed(seed, top, args.keep).n_contacts for seed in args.seeds]
    print(f"LS states at p = {top:g}: {np.mean(close):.0f} pairs with h < {WINDOW[0]:g} per "
          f"packing, against {np.mean(contacts):.0f} contacts after jamming")
    if len(args.pressures) > 1:
        spread = np.max(np.ptp(np.stack(list(phi.values())), axis=0))
        print(f"largest difference of phi_J between pressures for one seed: {spread:.1e}")


if __name__ == "__main__":
    main()
