"""Final error of `calippso.jam` against wall time, over convergence tolerances and backends.

For each dimension, one fixed input (an LS packing of N particles at reduced pressure 1e5,
seed 0; with --final-growth-rate R, an LS packing with a slow end: growth rate R from p = 1e3
on, the protocol of the validation ensembles) is jammed with every backend at every
tolerance pair (tol_gamma, tol_s). Errors of the final packing:

* |min gap|: the smallest h_ij = |r_ij|/σ_ij − 1 over touching pairs (0 for exact contacts;
  a negative value would be an overlap, −min gap);
* force balance: max_i |Σ_j f_ij n_ij| / mean force over stable particles;
* |isostaticity gap|: |N_c − d (N_s − 1) − 1|;
* |Δφ|: |φ − φ of the tightest run| (smallest tol_gamma, then tol_s, with HiGHS).

Run from the repository root (one jam of N = 1024, d = 3 takes 3-8 s from a slow-end input,
minutes from a constant-rate one; making a slow-end input takes LS 200-1000 s):

    python bench/error_vs_time.py
    python bench/error_vs_time.py --dims 3 --n 512 --solvers highs \
        --tolerances 1e-6:1e-4 1e-12:1e-9 --plot docs/images/error_vs_time.png
    python bench/error_vs_time.py --pressure 1e7 --final-growth-rate 1e-4   # slow-end inputs

Prints a Markdown table; writes the rows to --json and a figure per dimension to --plot
(the dimension is appended to the file name). `--replot a.json b.json` redraws and reprints
saved rows without running anything.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import calippso
from calippso.geometry.neighbors import NeighborSearch

DEFAULT_TOLERANCES = ["1e-5:1e-3", "1e-7:1e-5", "1e-9:1e-7", "1e-12:1e-9"]
ERRORS = {"min_gap_abs": "|min gap|", "force_balance": "force balance",
          "isostaticity_gap_abs": "|isostaticity gap|", "phi_error": "|φ − φ_tightest|"}


def ls_input(d: int, n: int, pressure: float, seed: int,
             final_growth_rate: float | None = None) -> calippso.Packing:
    """The fixed input: monodisperse LS packing at reduced pressure `pressure`, with a slow
    end (`final_growth_rate` from p = 1e3 on) when `final_growth_rate` is given."""
    import generators

    return generators.lubachevsky_stillinger(generators.diameters.monodisperse(n), d=d,
                                             target_pressure=pressure, seed=seed,
                                             final_growth_rate=final_growth_rate).packing


def run(packing: calippso.Packing, solver: str, tol_gamma: float, tol_s: float,
        max_iters: int) -> dict:
    """Jam once and measure the final errors."""
    start = time.perf_counter()
    result = calippso.jam(packing, solver=solver, tol_gamma=tol_gamma, tol_s=tol_s,
                          max_iters=max_iters)
    seconds = time.perf_counter() - start
    p = result.packing
    gaps = NeighborSearch(p.positions, p.diameters, p.box).pairs_within(
        1.1 * float(p.diameters.max())).gaps
    smallest, overlaps = float(gaps.min()), int(np.count_nonzero(gaps < 0))
    return {"d": p.d, "n": p.n, "solver": solver, "tol_gamma": tol_gamma, "tol_s": tol_s,
            "wall_time": seconds, "iterations": result.iterations,
            "converged": bool(result.converged), "phi": result.phi, "min_gap": smallest,
            "min_gap_abs": abs(smallest), "overlaps": overlaps,
            "force_balance": result.force_balance,
            "isostaticity_gap": result.isostaticity_gap,
            "isostaticity_gap_abs": abs(result.isostaticity_gap)}


def add_phi_error(rows: list[dict]) -> None:
    """|φ − φ_tightest| per dimension; the tightest run: HiGHS at the smallest tolerances."""
    for d in {r["d"] for r in rows}:
        same = [r for r in rows if r["d"] == d]
        tightest = min(same, key=lambda r: (r["solver"] != "highs", r["tol_gamma"], r["tol_s"]))
        for r in same:
            r["phi_error"] = abs(r["phi"] - tightest["phi"])


def table(rows: list[dict]) -> str:
    """The rows as a Markdown table."""
    lines = ["| d | N | solver | tol_gamma | tol_s | LPs | converged | wall time (s) | φ "
             "| min gap | force balance | isostaticity gap | abs(φ − φ_tightest) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['d']} | {r['n']} | {r['solver']} | {r['tol_gamma']:.0e} | "
                     f"{r['tol_s']:.0e} | {r['iterations']} | {'yes' if r['converged'] else 'no'}"
                     f" | {r['wall_time']:.1f} | {r['phi']:.10f} | {r['min_gap']:.1e} | "
                     f"{r['force_balance']:.1e} | {r['isostaticity_gap']} | "
                     f"{r['phi_error']:.1e} |")
    return "\n".join(lines)


def plot(rows: list[dict], path: Path) -> list[Path]:
    """One figure per dimension: the four errors against wall time (0 drawn at 1e-17)."""
    from calippso.reporting import pyplot

    plt = pyplot()
    written = []
    tolerances = sorted({(r["tol_gamma"], r["tol_s"]) for r in rows}, reverse=True)
    colors = {t: f"C{k}" for k, t in enumerate(tolerances)}
    markers = {"highs": "o", "clarabel": "s", "cvxpy": "^"}
    for d in sorted({r["d"] for r in rows}):
        fig, axes = plt.subplots(2, 2, figsize=(9, 6.5), sharex=True)
        for ax, (key, label) in zip(axes.ravel(), ERRORS.items()):
            integer = key == "isostaticity_gap_abs"
            for r in (r for r in rows if r["d"] == d):
                ax.plot(r["wall_time"], r[key] if integer else max(r[key], 1e-17),
                        markers.get(r["solver"], "x"),
                        color=colors[(r["tol_gamma"], r["tol_s"])], ms=7,
                        mfc="none" if not r["converged"] else None)
            ax.set_xscale("log")
            if integer:  # small integers: linear axis
                ax.set_ylim(-0.5, max(r[key] for r in rows if r["d"] == d) + 1.5)
            else:
                ax.set_yscale("log")
            ax.set_ylabel(label)
        for ax in axes[1]:
            ax.set_xlabel("wall time (s)")
        handles = [plt.Line2D([], [], color=colors[t], marker="o", ls="",
                              label=f"tol_gamma = {t[0]:.0e}, tol_s = {t[1]:.0e}")
                   for t in tolerances]
        handles += [plt.Line2D([], [], color="k", marker=m, ls="", label=s)
                    for s, m in markers.items() if any(r["solver"] == s for r in rows)]
        fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=7)
        n = next(r["n"] for r in rows if r["d"] == d)
        fig.suptitle(f"final error against wall time: d = {d}, N = {n} (open: not converged; "
                     f"0 drawn at 1e-17)", fontsize=10)
        fig.tight_layout(rect=(0, 0.08, 1, 1))
        target = path.with_name(f"{path.stem}_d{d}{path.suffix}")
        fig.savefig(target, dpi=120)
        plt.close(fig)
        written.append(target)
    return written


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dims", type=int, nargs="+", default=[3, 4])
    parser.add_argument("--n", type=int, default=1024)
    parser.add_argument("--solvers", nargs="+", default=["highs", "clarabel"])
    parser.add_argument("--tolerances", nargs="+", default=DEFAULT_TOLERANCES,
                        help="tol_gamma:tol_s pairs")
    parser.add_argument("--pressure", type=float, default=1e5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--final-growth-rate", type=float, default=None,
                        help="give the LS inputs a slow end: this growth rate from p = 1e3 on")
    parser.add_argument("--max-iters", type=int, default=1000)
    parser.add_argument("--json", type=Path, help="write the rows here")
    parser.add_argument("--plot", type=Path, help="figure path (d is appended to the name)")
    parser.add_argument("--replot", type=Path, nargs="+",
                        help="skip the runs: print and plot the rows of these --json files")
    args = parser.parse_args()

    if args.replot:
        rows = [row for path in args.replot for row in json.loads(path.read_text())]
        print(table(rows))
        for path in plot(rows, args.plot) if args.plot else []:
            print(f"wrote {path}")
        return
    tolerances = [tuple(float(v) for v in pair.split(":")) for pair in args.tolerances]
    rows = []
    for d in args.dims:
        start = time.perf_counter()
        packing = ls_input(d, args.n, args.pressure, args.seed, args.final_growth_rate)
        print(f"# d={d}: LS input made in {time.perf_counter() - start:.1f} s", flush=True)
        for solver in args.solvers:
            for tol_gamma, tol_s in tolerances:
                rows.append(run(packing, solver, tol_gamma, tol_s, args.max_iters))
                r = rows[-1]
                print(f"# d={d} {solver} tol_gamma={tol_gamma:.0e} tol_s={tol_s:.0e}: "
                      f"{r['wall_time']:.1f} s, {r['iterations']} LPs", flush=True)
    add_phi_error(rows)
    print(table(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    if args.plot:
        for path in plot(rows, args.plot):
            print(f"wrote {path}")


if __name__ == "__main__":
    main()
