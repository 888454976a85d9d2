"""`calippso.jam` between flat hard walls: one table row per (case, seed).

Every input is random sequential addition (φ = 0.45 in d = 2, 0.3 in d = 3;
`common.random_sequential_addition`) of monodisperse spheres in d = 3, and of the 50:50
mixture of discs with diameter ratio 1.4 in d = 2 (equal discs crystallise) between flat
walls, jammed by the LP loop (the stages that do not know walls yet are skipped). Run from
the repository root:

    python bench/walls.py --cases 2:128:x 2:256:x,y 3:128:x 3:256:x,y --seeds 1 2 3
    python bench/walls.py --cases 3:256:cylinder 2:128:cylinder --seeds 1 2 3
    python bench/walls.py --slab 8 12 16 --width 6 --seeds 1 2 3 --json slab.json

A case is d:N:axes (flat walls on those axes) or d:N:cylinder (a cylinder in x, y; in d = 2
a circle). Columns: N, d, container, seed, LPs, moves off a wall (converged hypostatic LPs
that `jam` pushed on), wall time (s), φ_J, particle and wall contacts, stable particles,
isostaticity gap (pair + wall contacts against d N_s + 1 − zero modes), force balance, the
net force on the walls (the largest |F_0 + F_L| / F_L over the walled axes; for a cylinder,
|Σ f_w e_w| / Σ f_w), and the largest relative mismatch of the pressure on a wall against
the virial: L_μ F_μ = Σ_pairs f r_μ²/|r| + Σ_walls f σ_i/2 for a flat wall, Σ_pairs f
|r_⊥|²/|r| = Σ_cylinder f (L/2 − σ_i/2) for a cylinder.

`--slab`: monodisperse spheres in d = 3 between walls at x = 0 and x = L (about the values
given, in final mean diameters), periodic in y and z with sides `--width`; the same box
fully periodic as the reference of the same protocol. φ_J(L) is fitted as φ_∞ − a/L (least
squares over every isostatic walled packing) and compared with the periodic mean.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

import calippso
from calippso import Boundaries
from calippso.geometry.packing import ball_volume

from common import random_sequential_addition

#: Packing fraction of the random sequential addition starts.
START_PHI = {2: 0.45, 3: 0.3}
#: Diameter ratio of the 50:50 mixture of discs in d = 2.
BIDISPERSE_RATIO = 1.4
#: Packing fraction used to choose N for a slab of the requested sides (near φ_J).
SLAB_PHI = 0.62


def checks(result) -> dict:
    """The row of one jammed packing (see the module docstring for the columns)."""
    packing = result.packing
    loads = result.wall_loads
    axes = packing.boundaries.wall_axes
    mismatch = max((abs(loads[a, 0] + loads[a, 1]) / loads[a, 1] for a in axes), default=0.0)
    vectors = result.contact_vectors
    distances = np.linalg.norm(vectors, axis=1)
    particle, wall = result.wall_contacts.T
    virial = 0.0
    for axis in axes:
        expected = (np.sum(result.forces * vectors[:, axis] ** 2 / distances)
                    + np.sum(result.wall_forces[wall // 2 == axis]
                             * packing.diameters[particle[wall // 2 == axis]] / 2))
        measured = result.wall_pressures[axis] * packing.volume
        virial = max(virial, float(np.max(np.abs(measured / expected - 1))))
    if packing.boundaries.cylinder_axes:
        plane = list(packing.boundaries.cylinder_axes)
        offset = packing.positions[particle][:, plane] - 0.5 * packing.box[plane]
        inward = -offset / np.linalg.norm(offset, axis=1)[:, None]
        net = np.linalg.norm(np.sum(result.wall_forces[:, None] * inward, axis=0))
        mismatch = max(mismatch, float(net / result.wall_forces.sum()))
        expected = np.sum(result.wall_forces * (0.5 * packing.box[plane[0]]
                                                - packing.diameters[particle] / 2))
        measured = np.sum(result.forces * np.sum(vectors[:, plane] ** 2, axis=1) / distances)
        virial = max(virial, abs(measured / expected - 1))
    return {"n": packing.n, "d": packing.d, "walls": packing.boundaries.describe(),
            "lps": result.iterations,
            "moves": sum("moved out of it" in note for note in result.notes),
            "seconds": result.wall_time, "phi": result.phi,
            "pair_contacts": int(result.contacts.shape[0]),
            "wall_contacts": result.n_wall_contacts, "stable": result.n_stable,
            "gap": result.isostaticity_gap, "balance": result.force_balance,
            "wall_mismatch": float(mismatch), "virial": virial,
            "converged": bool(result.converged)}


def run_cases(cases: list[str], seeds: list[int]) -> list[dict]:
    rows = []
    for case in cases:
        d, n, axes = case.split(":")
        d, n = int(d), int(n)
        boundaries = (Boundaries.cylinder(d, (0, 1)) if axes == "cylinder"
                      else Boundaries.walls(d, axes.split(",")))
        for seed in seeds:
            sizes = np.where(np.arange(n) < n // 2, 1.0, BIDISPERSE_RATIO) if d == 2 else None
            start = random_sequential_addition(n, d, START_PHI[d], seed, boundaries,
                                               diameters=sizes)
            row = checks(calippso.jam(start)) | {"seed": seed}
            rows.append(row)
            print(f"{row['n']:5d} {row['d']} {row['walls']:28s} {seed:3d} {row['lps']:4d} "
                  f"{row['moves']:3d} {row['seconds']:7.2f} {row['phi']:.6f} "
                  f"{row['pair_contacts']:6d} {row['wall_contacts']:5d} {row['stable']:5d} "
                  f"{row['gap']:+3d} {row['balance']:8.1e} {row['wall_mismatch']:8.1e} "
                  f"{row['virial']:8.1e}", flush=True)
    return rows


def run_slab(lengths: list[float], width: float, seeds: list[int]) -> list[dict]:
    rows = []
    for length in lengths:
        sides = np.array([length, width, width])
        n = int(round(SLAB_PHI * np.prod(sides) / float(ball_volume(3, 0.5))))
        for walled in (True, False):
            for seed in seeds:
                boundaries = Boundaries.walls(3, "x") if walled else None
                start = random_sequential_addition(n, 3, START_PHI[3], seed, boundaries, sides)
                result = calippso.jam(start)
                length = float(result.packing.box[0] / result.packing.mean_diameter)
                row = checks(result) | {"seed": seed, "length": length, "walled": walled}
                rows.append(row)
                print(f"L = {row['length']:6.2f} {'walls' if walled else 'periodic':8s} "
                      f"N = {n:5d} seed {seed}: phi_J {row['phi']:.5f}, {row['lps']} LPs, "
                      f"{row['seconds']:.0f} s, gap {row['gap']:+d}, moves {row['moves']}",
                      flush=True)
    walled = [row for row in rows if row["walled"] and row["gap"] == 0]
    periodic = [row["phi"] for row in rows if not row["walled"]]
    if len(walled) >= 2 and periodic:
        inverse = np.array([1.0 / row["length"] for row in walled])
        phi = np.array([row["phi"] for row in walled])
        slope, intercept = np.polyfit(inverse, phi, 1)
        print(f"fit phi_J(L) = {intercept:.4f} - {-slope:.3f}/L over {len(walled)} packings; "
              f"periodic, same protocol: {np.mean(periodic):.4f} +- "
              f"{np.std(periodic) / np.sqrt(len(periodic)):.4f}")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="*", default=[],
                        help="d:N:axes, e.g. 3:256:x,y")
    parser.add_argument("--slab", nargs="*", type=float, default=[],
                        help="wall separations L (diameters) of the slab study")
    parser.add_argument("--width", type=float, default=6.0,
                        help="periodic sides of the slab (diameters)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[1])
    parser.add_argument("--json", help="also write the rows to this JSON file")
    args = parser.parse_args()
    rows = run_cases(args.cases, args.seeds)
    if args.slab:
        rows += run_slab(args.slab, args.width, args.seeds)
    if args.json:
        with open(args.json, "w") as stream:
            json.dump(rows, stream, indent=1)


if __name__ == "__main__":
    main()
