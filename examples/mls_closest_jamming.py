"""Closest jamming (modified LS) of a random start, then CALiPPSO from that state.

Run time on one core, once Numba has compiled the generators: about 90 s (--tiny: 5 s).

MLS grows fast at first and ever slower near jamming, to stay in the start's basin; its
final packing is already near phi_J, and CALiPPSO certifies it (contacts, forces).

    python examples/mls_closest_jamming.py          # N = 256, d = 3
    python examples/mls_closest_jamming.py --tiny   # N = 48
"""

import argparse

import calippso
import generators


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=256, help="number of spheres")
    parser.add_argument("--tiny", action="store_true", help="N = 48, for a quick check")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    n = 48 if args.tiny else args.n

    mls = generators.closest_jamming(generators.diameters.monodisperse(n), 3, seed=args.seed,
                                     phi_start=0.3)
    print(
        f"MLS: phi = {mls.packing.phi:.6f}, p = {mls.reduced_pressure:.3g}, "
        f"{mls.wall_time:.1f} s ({mls.status})"
    )
    result = calippso.jam(mls.packing)
    print(result.summary())
    print(f"CALiPPSO moved phi by {result.phi - mls.packing.phi:+.2e}")


if __name__ == "__main__":
    main()
