"""Jam a 2D 50:50 bidisperse packing (size ratio 1.4) compressed by Lubachevsky–Stillinger.

Run time on one core, once Numba has compiled the generators: about 7 s (--tiny: 2 s).

The classic O'Hern et al. system: expect phi_J close to 0.84 and an isostatic contact network.

    python examples/ls_jam_2d_bidisperse.py            # N = 1024
    python examples/ls_jam_2d_bidisperse.py --tiny     # N = 64
"""

import argparse

import calippso
import generators


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1024, help="number of disks")
    parser.add_argument("--tiny", action="store_true", help="N = 64, for a quick check")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    n = 64 if args.tiny else args.n

    sizes = generators.diameters.bidisperse(n, ratio=1.4, seed=args.seed)
    start = generators.lubachevsky_stillinger(sizes, d=2, target_pressure=1e5, seed=args.seed)
    print(
        f"LS: phi = {start.packing.phi:.6f}, p = {start.reduced_pressure:.3g}, "
        f"{start.wall_time:.1f} s"
    )
    result = calippso.jam(start.packing)
    print(result.summary())


if __name__ == "__main__":
    main()
