"""Jam from a random, low-density start: Poisson centres, shrunk until nothing overlaps.

Run time on one core, once Numba has compiled the generators: about 45 s, some 470 LPs
(--tiny: 3 s).

No compression at all before CALiPPSO; the LPs do all the work (more of them than from a
compressed start), and phi_J comes out slightly lower than from an LS start.

    python examples/random_start.py          # N = 256, d = 3
    python examples/random_start.py --tiny   # N = 48
"""

import argparse

import calippso
import generators
from calippso.geometry.neighbors import contact_shrink


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=256, help="number of spheres")
    parser.add_argument("--d", type=int, default=3, help="dimension")
    parser.add_argument("--tiny", action="store_true", help="N = 48, for a quick check")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    n = 48 if args.tiny else args.n

    points = generators.poisson(
        generators.diameters.monodisperse(n), args.d, phi=0.3, seed=args.seed
    )
    shrink = contact_shrink(points.positions, points.diameters, points.box)
    start = points.scaled_to_phi(points.phi * shrink**args.d)
    print(f"random start: phi = {start.phi:.3g} (no overlap)")
    result = calippso.jam(start)
    print(result.summary())


if __name__ == "__main__":
    main()
