"""Jam equal spheres in a cylinder (or between two flat walls) and show their layering at
the wall.

Run time on one core, once Numba has compiled the generators: about 15 s in the cylinder
(--tiny: 6 s), about 17 s between walls (--walls; --tiny: 3 s), imports included.

In the cylinder (axis along z, diameter the box side), the start is random: Poisson centres
inside the circle, shrunk until nothing overlaps; `calippso.jam` then runs the LP loop from
there. Between walls at x = 0 and x = L (--walls), a soft-sphere quench makes a start that
`jam` certifies at once. The layering profile (`calippso.analysis.density_profile`) is the
packing fraction in thin shells parallel to the wall against their distance from it: near 0
at the wall, a dense first layer half a diameter from it, decaying oscillations, and about
the bulk value further in.

    python examples/walls_layering.py                           # N = 192 in a cylinder
    python examples/walls_layering.py --walls                   # N = 512 between walls
    python examples/walls_layering.py --tiny --picture --out .  # N = 64, and layering.png
"""

import argparse
from pathlib import Path

import numpy as np

import calippso
import generators
from calippso import Boundaries
from calippso.analysis import density_profile
from calippso.geometry.neighbors import contact_shrink

#: Bins of the printed profile and of the picture, in mean diameters.
TABLE_BIN, PICTURE_BIN = 0.25, 0.05
#: Number of spheres (default, --tiny) in each container.
SIZES = {"cylinder": (192, 64), "walls": (512, 128)}
#: Packing fraction of the random centres of the cylinder's start, before the shrink.
START_PHI = 0.3


def cylinder_start(n: int, seed: int) -> calippso.Packing:
    """Random centres inside a cylinder over x and y, shrunk to no overlap."""
    points = generators.poisson(generators.diameters.monodisperse(n), 3, phi=START_PHI,
                                seed=seed, boundaries=Boundaries.cylinder(3, ["x", "y"]))
    shrink = contact_shrink(points.positions, points.diameters, points.box)
    return points.scaled_to_phi(points.phi * shrink ** 3)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=None,
                        help="number of spheres (default 192 in the cylinder, 512 between walls)")
    parser.add_argument("--walls", action="store_true", help="flat walls in x, not a cylinder")
    parser.add_argument("--tiny", action="store_true", help="N = 64 (128 between walls)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--picture", action="store_true", help="draw layering.png (matplotlib)")
    parser.add_argument("--out", type=Path, default=Path("."), help="folder of the picture")
    args = parser.parse_args(argv)
    n = args.n or SIZES["walls" if args.walls else "cylinder"][args.tiny]

    if args.walls:
        quench = generators.soft_quench(generators.diameters.monodisperse(n), 3,
                                        seed=args.seed, boundaries=Boundaries.walls(3, ["x"]))
        result = calippso.jam(quench.packing, network=quench.contacts)
    else:
        result = calippso.jam(cylinder_start(n, args.seed))
    print(result.summary())

    middle = result.packing.box[0] / 2 / result.packing.mean_diameter
    profile = density_profile(result, bins=np.arange(0.0, middle, TABLE_BIN))
    print("distance from the wall (diameters)   local phi")
    for distance, phi in zip(profile.distance, profile.phi):
        print(f"  {distance:5.2f}   {phi:.3f}  {'#' * int(round(40 * phi))}")
    print(f"phi of the whole packing {result.phi:.4f}")

    if args.picture:
        from calippso.reporting import pyplot

        fine = density_profile(result, bins=np.arange(0.0, middle, PICTURE_BIN))
        figure, axis = pyplot().subplots(figsize=(6.4, 4.0))
        axis.plot(fine.distance, fine.phi, "k-", lw=1.2, label="φ(s)")
        axis.axhline(result.phi, color="C1", ls="--", label=f"φ_J = {result.phi:.4f}")
        axis.set_xlabel("s, distance from the wall (mean diameters)")
        axis.set_ylabel("local packing fraction")
        axis.set_title(f"N = {n} equal spheres, {result.packing.boundaries.describe()}")
        axis.legend()
        args.out.mkdir(parents=True, exist_ok=True)
        path = args.out / "layering.png"
        figure.tight_layout()
        figure.savefig(path, dpi=120)
        pyplot().close(figure)
        print(f"-> {path}")


if __name__ == "__main__":
    main()
