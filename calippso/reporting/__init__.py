"""Reports: a summary JSON, PNG figures and a Markdown page for one run or an ensemble.

`report` is exposed as `calippso.report`. matplotlib (the optional extra ``plot``) is
imported only when a figure is drawn, on the Agg backend; `pyplot` gives that same headless
``matplotlib.pyplot`` to other figures drawn beside the reports.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..analysis import analyze
from ..analysis._inputs import as_results
from ..analysis.finite_size import finite_size_analysis, sizes_of
from ..analysis.gaps import DEFAULT_MAX_GAP
from ..result import JammingResult
from ._matplotlib import pyplot
from .figures import plot_contact_numbers, plot_forces, plot_gaps, plot_history, plot_walls
from .page import markdown
from .size_figures import plot_exponents_vs_n, plot_gap_collapse
from .summary_json import summary_dict, write_json

__all__ = ["report", "plot_forces", "plot_gaps", "plot_contact_numbers", "plot_history",
           "plot_walls", "plot_exponents_vs_n", "plot_gap_collapse", "pyplot"]


def report(results: JammingResult | Iterable[JammingResult], out_dir: str | os.PathLike, *,
           title: str | None = None, max_gap: float = DEFAULT_MAX_GAP, rule: str = "bucklers",
           model: str | dict[str, str] | None = None, n_bootstrap: int = 1000,
           seed: int = 0, max_history_figures: int | None = None, correction: str = "auto",
           omega: float | None = None, gap_floor: str = "rank") -> Path:
    """Analyse one jammed packing or pool an ensemble, and write the report into `out_dir`.

    Files written: ``summary.json`` (φ, z, rattlers, isostaticity, exponents with intervals,
    one record per run), ``forces.png``, ``gaps.png``, ``contact_numbers.png``,
    ``history/run_<k>.png`` (error against wall time, one per run) and ``report.md``. When a
    packing has walls, also ``walls.png`` (wall forces and the layering profile) and a
    "walls" entry in ``summary.json`` (wall forces, loads and pressures, layering); the force
    distributions and exponents hold the particle–particle forces only.

    Packings of several sizes are pooled as above and also grouped by their number of
    particles N (`calippso.analysis.finite_size_analysis`): ``summary.json`` gains
    "by_size" (per N: the packings and each exponent's value and interval), "extrapolated"
    (each exponent's limit N → ∞ with its interval and correction form) and "gap_cutoff"
    (h_min(N) and the γ of its scaling), and the report draws ``exponents_vs_n.png`` and
    ``gaps_collapse.png``.

    Parameters
    ----------
    results : JammingResult or iterable of JammingResult
        Packings of one dimension.
    out_dir : str or PathLike
        Folder (created if needed; files of an earlier report are overwritten).
    title : str, optional
        Page title (default: "Jammed packings, d = …").
    max_gap : float
        Largest gap collected (`calippso.analysis.gaps`).
    rule : {"bucklers", "weakest", "response"}
        Localisation rule (`calippso.analysis.forces.localized_contacts`).
    model : None, str or dict
        Models of the exponent fits (`calippso.analysis.exponents.resolve_models`; default:
        "power_law" for γ, "auto" for the force exponents).
    n_bootstrap : int
        Bootstrap resamples per exponent.
    seed : int
        Seed of the bootstrap.
    max_history_figures : int, optional
        Draw the history of at most this many runs (the first ones); default: all.
    correction : {"auto", "constant", "inverse_n", "power"}
        Correction form of the extrapolation to N → ∞, for packings of several sizes
        (`calippso.analysis.extrapolation`).
    omega : float, optional
        Fix ω of the correction form "power".
    gap_floor : {"rank", "cutoff"}
        Packings of several sizes: where the γ window of each size starts
        (`calippso.analysis.finite_size_analysis`).

    Returns
    -------
    Path
        The path of ``report.md``.

    Raises
    ------
    ValueError, TypeError
        Empty input, mixed dimensions, or an element that is not a `JammingResult`.
    ImportError
        matplotlib is not installed.
    """
    items = as_results(results)
    out = Path(out_dir)
    (out / "history").mkdir(parents=True, exist_ok=True)
    analysis = analyze(items, max_gap=max_gap, rule=rule, model=model, n_bootstrap=n_bootstrap,
                       seed=seed)
    figures = {"forces": plot_forces(analysis, out / "forces.png"),
               "gaps": plot_gaps(analysis, out / "gaps.png"),
               "contacts": plot_contact_numbers(analysis, out / "contact_numbers.png")}
    if analysis.layering is not None:
        figures["walls"] = plot_walls(analysis, out / "walls.png")
    sizes = None
    if np.unique(sizes_of(items)).size > 1:
        samples = {"gamma": analysis.gaps, "theta_e": analysis.forces["extended"],
                   "theta_l": analysis.forces["localized"], "theta": analysis.forces["all"]}
        sizes = finite_size_analysis(items, max_gap=max_gap, rule=rule, model=model,
                                     form=correction, omega=omega, gap_floor=gap_floor,
                                     samples=samples,
                                     n_bootstrap=n_bootstrap, seed=seed)
        figures["exponents_vs_n"] = plot_exponents_vs_n(sizes, out / "exponents_vs_n.png")
        figures["gaps_collapse"] = plot_gap_collapse(sizes, out / "gaps_collapse.png")
    drawn = items if max_history_figures is None else items[:max_history_figures]
    histories = [plot_history(r, out / "history" / f"run_{k}.png",
                              title=f"run {k}: N = {r.packing.n}, d = {r.d}, {r.solver}, "
                                    f"{r.iterations} LPs, {r.wall_time:.1f} s")
                 for k, r in enumerate(drawn) if r.history.shape[0]]
    summary = summary_dict(analysis, items)
    if sizes is not None:
        summary.update(sizes.to_dict())
    summary["figures"] = {**{k: p.name for k, p in figures.items()},
                          "history": [f"history/{p.name}" for p in histories]}
    write_json(summary, out / "summary.json")
    page = out / "report.md"
    page.write_text(markdown(summary, figures, histories,
                             title or f"Jammed packings, d = {analysis.contacts.d}"))
    return page
