"""Benchmark and validation sweep of the force-biased spherocylinder generator.

    python bench/spherocylinders.py --json speed.json    # wall time, N = 2000, γ = 0.4 and 10
    python bench/spherocylinders.py sweep --seeds 0 1 --json sweep.json
    python bench/spherocylinders.py sweep --n 3000 --gammas 20 --json g20.json --checkpoints ckpt
    python bench/spherocylinders.py plot sweep.json [more.json …] --image docs/images/x.png
    python bench/spherocylinders.py pairs --n 3000 --gamma 20   # one pair-list build at the start

`--json PATH` writes the rows to a JSON file; `sweep` keeps the rows already in it and adds
each run's row as the run ends.

Run long jobs under ``nice -n 10``. Wall times include Numba compilation only on a cold cache.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from generators.spherocylinders import force_biased, min_distance_ratio, overlapping_pairs
from generators.spherocylinders.fb import (estimated_density, rigid_body_eps_rot,
                                           start_density)


#: Label of the rows made with the default start.
DEFAULT_START = "η₀ = min(1.2, 12/γ)"
#: Label of long-rod rows started at 1.2, the default before η₀ γ = 12 (shown in the η₀ scan).
FORMER_LONG_ROD_START = "η₀ = 1.2 (γ > 10)"


def run_one(n: int, gamma: float, seed: int, checkpoint: Path | None = None,
            **options) -> dict:
    """One packing: φ, S, steps, wall time (of all calls, when resumed from `checkpoint`) and
    the exact-distance overlap check."""
    result = force_biased(n, gamma, seed=seed, checkpoint=checkpoint, **options)
    wall = result.wall_time
    packing = result.packing
    meetings = result.history["phi"][result.history["rate"] == 0.0]
    return {"n": n, "gamma": gamma, "seed": seed, **options,
            "eps_rot_used": options.get("eps_rot", float(rigid_body_eps_rot(gamma))),
            "initial_density_used": result.extra["initial_density"],
            "phi": packing.phi, "contact_p2": contact_alignment(packing),
            "S": packing.nematic_order(), "steps": result.steps, "wall_time": wall,
            "phi_first_meeting": float(meetings[0]) if len(meetings) else None,
            "min_distance_ratio": min_distance_ratio(packing), "status": result.status}


def contact_alignment(packing, within: float = 0.01) -> float:
    """Mean P2(u_i · u_j) = ⟨1.5 (u_i · u_j)² − 0.5⟩ over pairs closer than (1 + within) σ_ij.

    0 for contacts between randomly oriented rods, 1 for parallel ones: local alignment that
    the global nematic order S averages away.
    """
    pairs = overlapping_pairs(packing, -within)
    if len(pairs) == 0:
        return float("nan")
    cosines = np.einsum("ij,ij->i", packing.axes[pairs[:, 0]], packing.axes[pairs[:, 1]])
    return float(np.mean(1.5 * cosines**2 - 0.5))


def pair_list_timing(n: int, gamma: float, initial_density: float | None = None,
                     repeats: int = 3) -> dict:
    """Time `cells.pair_list` on a start (Poisson centres, random axes) at nominal density
    `initial_density`, by default the generator's min(1.2, 12/γ); print and return the row."""
    import math

    from generators.spherocylinders.cells import pair_list
    from generators.spherocylinders.fb import SKIN, pair_list_skin

    d0 = np.full(n, (1.5 * gamma + 1.0) ** (-1.0 / 3.0))
    h0 = 0.5 * gamma * d0
    eta0 = start_density(gamma) if initial_density is None else initial_density
    box = np.full(3, (n * math.pi / 6.0 / eta0) ** (1.0 / 3.0))
    rng = np.random.default_rng(0)
    positions = rng.uniform(0.0, box[0], (n, 3))
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    skin = pair_list_skin(1.0, h0, d0, box, SKIN * float(d0.max()))
    pair_list(positions[:50], axes[:50], h0[:50], d0[:50], box, skin)  # compile first
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        pairs = pair_list(positions, axes, h0, d0, box, skin)
        times.append(time.perf_counter() - started)
    print(f"N = {n}, γ = {gamma:g}, η₀ = {eta0:g}: {len(pairs)} pairs, "
          f"best of {repeats} builds {min(times):.3f} s")
    return {"n": n, "gamma": gamma, "initial_density_used": eta0, "pairs": len(pairs),
            "repeats": repeats, "best_seconds": min(times)}


def bench(n: int) -> list[dict]:
    """Wall time of one packing at γ = 0.4 and at γ = 10 (seed 0): print and return the rows."""
    force_biased(100, 0.4, contraction_rate=1e-2)  # compile (or load the cache) first
    rows = []
    for gamma in (0.4, 10.0):
        row = run_one(n, gamma, 0)
        rows.append(row)
        print(f"N = {n}, γ = {gamma:4}: {row['wall_time']:7.1f} s, {row['steps']} steps, "
              f"φ = {row['phi']:.4f}, S = {row['S']:.3f}")
    return rows


def sweep(n: int, gammas: list[float], seeds: list[int], out: Path,
          checkpoints: Path | None = None, **options) -> None:
    """Run every (γ, seed), appending one row each to the JSON file `out`; with `checkpoints`,
    each run keeps a checkpoint there (named by N, γ, seed and options), so a killed sweep
    resumes the run it was in."""
    rows = json.loads(out.read_text()) if out.exists() else []
    options = {key: value for key, value in options.items() if value is not None}
    if checkpoints is not None:
        checkpoints.mkdir(parents=True, exist_ok=True)
    for gamma in gammas:
        for seed in seeds:
            name = "_".join([f"n{n}", f"g{gamma:g}", f"s{seed}",
                             *(f"{key}{value:g}" for key, value in sorted(options.items()))])
            checkpoint = None if checkpoints is None else checkpoints / f"{name}.npz"
            row = run_one(n, gamma, seed, checkpoint=checkpoint, **options)
            rows.append(row)
            out.write_text(json.dumps(rows, indent=1))
            print(f"γ = {gamma:5}, seed {seed}: φ = {row['phi']:.4f}, S = {row['S']:.3f}, "
                  f"{row['steps']} steps, {row['wall_time']:.0f} s, "
                  f"min δ/σ = {row['min_distance_ratio']:.12f}", flush=True)


def _rotation(row: dict) -> str:
    """A row's rotation step: the rigid-body default, 3× it, or Bargiel's fixed ε_r."""
    value = row.get("eps_rot")
    if value is None:
        return "rigid-body ε_r"
    tripled = 3 * float(rigid_body_eps_rot(row["gamma"]))
    if tripled > 0 and abs(value / tripled - 1) < 0.01:
        return "3× rigid-body ε_r"
    return f"ε_r = {value:g}"


def row_start_density(row: dict) -> float:
    """η₀ of a row; rows made before the bench recorded it used 1.2 × estimated_density."""
    if row.get("former_start"):
        return 1.2 * estimated_density(row["gamma"])
    return row["initial_density_used"]


def _start(row: dict) -> str:
    if row.get("former_start"):
        return "former start 1.2 × min(0.70, 4.5/γ)"
    if row["initial_density_used"] == start_density(row["gamma"]):
        return DEFAULT_START
    if row["initial_density_used"] == 1.2:
        return FORMER_LONG_ROD_START
    return "start lowered by the box rule"


def plot(files: list[Path], image: Path) -> None:
    """φ(γ), φ γ(γ) and S(γ) at τ = 1e-4, N ≥ 2000 with the default start rule, one curve per
    rotation step and start; and φ γ against the start density η₀ at γ = 10."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [row for file in files for row in json.loads(file.read_text())]
    figure, (left, middle, right, scan) = plt.subplots(1, 4, figsize=(19, 4.4))
    swept = [row for row in rows if row.get("contraction_rate", 1e-4) == 1e-4
             and row["n"] >= 2000 and _start(row) != FORMER_LONG_ROD_START
             and row.get("initial_density", start_density(row["gamma"]))
             == start_density(row["gamma"])]
    labels = sorted({(_rotation(row), _start(row)) for row in swept},
                    key=lambda key: (key[0] != "rigid-body ε_r", key[1] != DEFAULT_START, key))
    for rotation, start in labels:
        chosen = [row for row in swept if (_rotation(row), _start(row)) == (rotation, start)]
        gammas = sorted({row["gamma"] for row in chosen})
        phi = [[row["phi"] for row in chosen if row["gamma"] == g] for g in gammas]
        order = [[row["S"] for row in chosen if row["gamma"] == g] for g in gammas]
        default = rotation == "rigid-body ε_r" and start == DEFAULT_START
        style = dict(marker="o" if start == DEFAULT_START else "s", capsize=3,
                     lw=2.2 if default else 1.0, label=f"{rotation}, {start}"
                     + (" (default)" if default else ""))
        left.errorbar(gammas, [np.mean(p) for p in phi], [np.std(p) for p in phi], **style)
        middle.errorbar(gammas, [np.mean(p) * g for p, g in zip(phi, gammas)],
                        [np.std(p) * g for p, g in zip(phi, gammas)], **style)
        style.pop("capsize")
        right.plot(gammas, [np.mean(s) for s in order], **style)
    reference = np.linspace(4, 90, 100)
    left.plot(reference, 4.5 / reference, "k--", lw=1, label="φ = 4.5/γ (Bargiel)")
    left.plot([0.4], [0.705], "k*", ms=10, label="Bargiel max 0.705")
    left.set(xlabel="aspect ratio γ = l/d", ylabel="φ", yscale="log", ylim=(0.1, 0.8))
    for axis in (middle, scan):
        axis.axhspan(4.5 * 0.85, 4.5 * 1.15, color="0.85", label="Bargiel 4.5 ± 15 %")
        axis.axhline(5.4, color="k", ls=":", lw=1, label="Williams–Philipse 5.4")
    middle.set(xlabel="aspect ratio γ = l/d", ylabel="φ γ", ylim=(0, 8))
    right.set(xlabel="aspect ratio γ = l/d", ylabel="nematic order S", yscale="log",
              ylim=(0.005, 1.5))
    right.axhline(0.05, color="k", ls=":", lw=1)
    for axis in (left, middle, right):
        axis.set_xscale("symlog", linthresh=1.0)
        axis.set_xlim(-0.1, 30)
    left.legend(fontsize=6.5, loc="lower left")
    middle.legend(fontsize=6.5, loc="upper left")
    for gamma, colour in ((10.0, "C0"), (20.0, "C3")):
        scanned = [row for row in rows if row["gamma"] == gamma and row["n"] >= 2000
                   and row.get("contraction_rate", 1e-4) == 1e-4
                   and _rotation(row) == "rigid-body ε_r"]
        starts = np.array([row_start_density(row) for row in scanned])
        scan.plot(starts, [gamma * row["phi"] for row in scanned], "o", color=colour,
                  label=f"γ = {gamma:g}, rigid-body ε_r, τ = 1e-4")
        scan.axvline(start_density(gamma), color=colour, ls=":", lw=1)
    scan.set(xlabel="start density η₀ (dotted: the default min(1.2, 12/γ))", ylabel="φ γ",
             ylim=(3, 7), xlim=(0.3, 1.6))
    scan.legend(fontsize=6.5, loc="upper left")
    figure.tight_layout()
    figure.savefig(image, dpi=110)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command")
    parser.add_argument("--n", type=int, default=2000, help="particles (default 2000)")
    parser.add_argument("--json", type=Path, default=None,
                        help="write the rows of the default run or of `pairs` here")
    run = sub.add_parser("sweep")
    # the same option after the subcommand; SUPPRESS keeps a value given before it
    run.add_argument("--n", type=int, default=argparse.SUPPRESS, help="particles (default 2000)")
    run.add_argument("--gammas", type=float, nargs="+", default=[0.0, 0.4, 1.0, 2.0, 5.0, 10.0])
    run.add_argument("--seeds", type=int, nargs="+", default=[0])
    run.add_argument("--eps-rot", type=float, default=None,
                     help="Bargiel's ε_r; default: the rigid-body value of each aspect ratio")
    run.add_argument("--contraction-rate", type=float, default=1e-4)
    run.add_argument("--initial-density", type=float, default=None,
                     help="nominal density of the start; default: min(1.2, 12/γ) if the box "
                          "allows it")
    run.add_argument("--json", type=Path, required=True,
                     help="JSON file of the rows; rows already in it are kept")
    run.add_argument("--checkpoints", type=Path, default=None,
                     help="folder for one checkpoint per run: a killed sweep resumes its run")
    pairs = sub.add_parser("pairs")
    pairs.add_argument("--n", type=int, default=5500)
    pairs.add_argument("--gamma", type=float, default=20.0)
    pairs.add_argument("--json", type=Path, default=argparse.SUPPRESS, help="write the row here")
    pairs.add_argument("--initial-density", type=float, default=None,
                       help="nominal density of the start; default: min(1.2, 12/γ)")
    draw = sub.add_parser("plot")
    draw.add_argument("files", type=Path, nargs="+")
    draw.add_argument("--image", type=Path, required=True)
    arguments = parser.parse_args()
    if arguments.command == "sweep":
        sweep(arguments.n, arguments.gammas, arguments.seeds, arguments.json,
              eps_rot=arguments.eps_rot, contraction_rate=arguments.contraction_rate,
              initial_density=arguments.initial_density, checkpoints=arguments.checkpoints)
        return
    if arguments.command == "plot":
        plot(arguments.files, arguments.image)
        return
    if arguments.command == "pairs":
        rows = [pair_list_timing(arguments.n, arguments.gamma, arguments.initial_density)]
    else:
        rows = bench(arguments.n)
    if arguments.json:
        arguments.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
