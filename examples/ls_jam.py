"""Jam monodisperse hard spheres compressed by Lubachevsky–Stillinger, in d = 3, 4 or 5.

Run time on one core, once Numba has compiled the generators: about 7 s (d = 3), 6 s
(d = 4), 13 s (d = 5); --tiny 2–5 s.

Expected phi_J: about 0.64 (d = 3), 0.46 (d = 4), 0.31 (d = 5), slightly lower for small N.

    python examples/ls_jam.py --d 3        # N = 512
    python examples/ls_jam.py --d 5        # N = 256 (also d = 4)
    python examples/ls_jam.py --d 4 --tiny # N = 64 (128 in d = 5)
"""

import argparse

import calippso
import generators

DEFAULT_N = {3: 512, 4: 256, 5: 256}
TINY_N = {3: 64, 4: 64, 5: 128}  # d = 5 needs N = 128 for a box wider than two diameters


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--d", type=int, choices=sorted(DEFAULT_N), default=3, help="dimension")
    parser.add_argument("--n", type=int, help="number of spheres (default by d: 512, 256, 256)")
    parser.add_argument(
        "--tiny", action="store_true", help="N = 64 (128 in d = 5), for a quick check"
    )
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    n = TINY_N[args.d] if args.tiny else args.n or DEFAULT_N[args.d]

    sizes = generators.diameters.monodisperse(n)
    start = generators.lubachevsky_stillinger(sizes, d=args.d, target_pressure=1e5, seed=args.seed)
    print(
        f"LS: phi = {start.packing.phi:.6f}, p = {start.reduced_pressure:.3g}, "
        f"{start.wall_time:.1f} s"
    )
    result = calippso.jam(start.packing)
    print(result.summary())


if __name__ == "__main__":
    main()
