"""A random dense packing of spherocylinders (force-biased, Bargiel), written for OVITO.

Run time on one core, once Numba has compiled the generators: about 5 s (--tiny: 1 s),
without the picture.

python examples/spherocylinders.py                     # N = 500, aspect ratio 0.4
python examples/spherocylinders.py --tiny --out /tmp   # N = 100
python examples/spherocylinders.py --picture           # also a PNG (POV-Ray or matplotlib)
"""

import argparse
from pathlib import Path

from generators import spherocylinders


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=500, help="number of particles")
    parser.add_argument(
        "--aspect-ratio", type=float, default=0.4, help="cylinder length / diameter"
    )
    parser.add_argument("--tiny", action="store_true", help="N = 100 and a fast contraction")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("."), help="folder for the .xyz file")
    parser.add_argument("--picture", action="store_true",
                        help="also draw spherocylinders.png (needs matplotlib or POV-Ray)")
    args = parser.parse_args(argv)
    n, rate = (100, 1e-2) if args.tiny else (args.n, 1e-4)

    made = spherocylinders.force_biased(n, args.aspect_ratio, contraction_rate=rate, seed=args.seed)
    packing = made.packing
    path = spherocylinders.write_xyz(packing, args.out / "spherocylinders.xyz")
    print(
        f"N = {n}, aspect ratio {args.aspect_ratio}: phi = {packing.phi:.4f}, "
        f"nematic order S = {packing.nematic_order():.3f}, {made.wall_time:.1f} s -> {path}"
    )
    if args.picture:
        print(f"picture -> {spherocylinders.render(packing, args.out / 'spherocylinders.png')}")


if __name__ == "__main__":
    main()
