"""Jam equal spheres between two flat walls and show their layering at the walls.

Run time on one core, once Numba has compiled the generators: about 19 s (--tiny: 10 s),
imports included.

A soft-sphere quench between walls at x = 0 and x = L (periodic in y and z) makes the start;
`calippso.jam` certifies its jamming point with the wall contacts. The layering profile
(`calippso.analysis.density_profile`) is the packing fraction in thin slabs parallel to the
walls, against their distance from the nearest wall: near 0 at the wall, a dense first layer
half a diameter from it, a few decaying oscillations, and the bulk value in the middle.

    python examples/walls_layering.py                           # N = 512, d = 3
    python examples/walls_layering.py --tiny --picture --out .  # N = 128, and layering.png
"""

import argparse
from pathlib import Path

import numpy as np

import calippso
import generators
from calippso import Boundaries
from calippso.analysis import density_profile

#: Bins of the printed profile and of the picture, in mean diameters.
TABLE_BIN, PICTURE_BIN = 0.25, 0.05
#: Where the middle of the slab starts, in mean diameters from the nearest wall.
MIDDLE = 2.0


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=512, help="number of spheres")
    parser.add_argument("--tiny", action="store_true", help="N = 128, for a quick check")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--picture", action="store_true", help="draw layering.png (matplotlib)")
    parser.add_argument("--out", type=Path, default=Path("."), help="folder of the picture")
    args = parser.parse_args(argv)
    n = 128 if args.tiny else args.n

    walls = Boundaries.walls(3, ["x"])
    quench = generators.soft_quench(generators.diameters.monodisperse(n), 3, seed=args.seed,
                                    boundaries=walls)
    result = calippso.jam(quench.packing, network=quench.contacts)
    print(result.summary())

    half = result.packing.box[0] / 2 / result.packing.mean_diameter
    profile = density_profile(result, bins=np.arange(0.0, half, TABLE_BIN))
    print("distance from the wall (diameters)   local phi")
    for distance, phi in zip(profile.distance, profile.phi):
        print(f"  {distance:5.2f}   {phi:.3f}  {'#' * int(round(40 * phi))}")
    middle = profile.phi[profile.distance > MIDDLE]
    print(f"phi of the whole packing {result.phi:.4f}; mean beyond {MIDDLE:g} diameters from "
          f"the walls {np.mean(middle):.4f}")

    if args.picture:
        from calippso.reporting import pyplot

        fine = density_profile(result, bins=np.arange(0.0, half, PICTURE_BIN))
        figure, axis = pyplot().subplots(figsize=(6.4, 4.0))
        axis.plot(fine.distance, fine.phi, "k-", lw=1.2, label="φ(s)")
        axis.axhline(result.phi, color="C1", ls="--", label=f"φ_J = {result.phi:.4f}")
        axis.set_xlabel("s, distance from the nearest wall (mean diameters)")
        axis.set_ylabel("local packing fraction")
        axis.set_title(f"N = {n} equal spheres between walls in x, jammed")
        axis.legend()
        args.out.mkdir(parents=True, exist_ok=True)
        path = args.out / "layering.png"
        figure.tight_layout()
        figure.savefig(path, dpi=120)
        pyplot().close(figure)
        print(f"-> {path}")


if __name__ == "__main__":
    main()
