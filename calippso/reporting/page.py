"""The report page (Markdown) that shows the summary figures and plots."""

from __future__ import annotations

from pathlib import Path

__all__ = ["markdown"]

_NAMES = {"gamma": ("γ", "gaps, Z(h) − z ~ h^(1−γ)"),
          "theta_e": ("θ_e", "extended forces, G_e(f) ~ f^(1+θ_e)"),
          "theta_l": ("θ_ℓ", "localised forces, G_ℓ(f) ~ f^(1+θ_ℓ)"),
          "theta": ("θ", "all forces, G(f) ~ f^(1+θ); theory: min(θ_ℓ, θ_e)")}


def _fmt(value, digits: int = 4) -> str:
    """`value` to `digits` significant digits; "—" for None and NaN."""
    return "—" if value is None or value != value else f"{value:.{digits}g}"


def _model(exponent: dict) -> str:
    """"power law" or "cut-off λ = …", with the likelihood-ratio p-value of the pure law."""
    p_value = exponent.get("power_law_p_value")
    test = "" if p_value is None or p_value != p_value else f" (p = {p_value:.2g})"
    if exponent.get("model") == "cutoff":
        return f"cut-off λ = {exponent['cutoff']:.3g}{test}"
    return f"power law{test}"


def markdown(summary: dict, figures: dict[str, Path], histories: list[Path],
             title: str) -> str:
    """The page, with figure links relative to the report folder.

    Parameters
    ----------
    summary : dict
        `summary.summary_dict` output.
    figures : dict
        "forces", "gaps", "contacts" (and "walls" for packings with walls) → PNG paths (file
        names are used).
    histories : list of Path
        One PNG per run.
    title : str
    """
    phi = summary["phi"]
    lines = [
        f"# {title}", "",
        f"{summary['packings']} packing(s) of {summary['particles']} particles in total, "
        f"d = {summary['d']}; localisation rule \"{summary['localization_rule']}\". "
        "Numbers in `summary.json`.", "",
        "| quantity | value |", "|---|---|",
        f"| φ (mean ± std) | {phi['mean']:.6f} ± {phi['std']:.6f} |",
        f"| φ range | [{phi['min']:.6f}, {phi['max']:.6f}] |",
        f"| mean z over stable particles | {summary['mean_z_stable']:.5f} |",
        f"| rattler fraction | {100 * summary['rattler_fraction']:.3f} % |",
        f"| isostatic packings | {summary['isostatic_packings']} / {summary['packings']} |",
        f"| pairs touching outside the networks (zero force, not counted as contacts) | "
        f"{summary['touching_outside_network']} |",
        f"| bucklers (d + 1 contacts) | {summary['bucklers']} "
        f"({100 * summary['buckler_fraction']:.2f} % of stable) |",
        f"| localised / extended forces (particle–particle) | {summary['localized_forces']} / "
        f"{summary['extended_forces']} |",
        f"| jam wall time (total, mean per run) | {summary['jam_wall_time_s']['total']:.1f} s, "
        f"{summary['jam_wall_time_s']['mean']:.1f} s |",
        "", "## Exponents", "",
        "| exponent | fitted | 95 % interval | reference | window | points | model "
        "(power-law p-value) | bootstrap over |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, (symbol, what) in _NAMES.items():
        e = summary["exponents"].get(name)
        if e is None:
            reason = summary["exponent_errors"].get(name, "not fitted")
            reference = summary["reference_exponents"][name]
            lines.append(f"| {symbol} ({what}) | — | — | {reference:g} | not fitted: {reason} "
                         "| | |")
            continue
        low, high = e["interval"]
        value = _fmt(e["value"]) + (" (few values)" if e.get("warning") else "")
        lines.append(f"| {symbol} ({what}) | {value} | [{_fmt(low)}, {_fmt(high)}] "
                     f"| {e['reference']:g} | [{_fmt(e['window'][0], 3)}, "
                     f"{_fmt(e['window'][1], 3)}] | {e['points_in_window']} "
                     f"| {_model(e)} | {e['bootstrap_over']} |")
    for warning in summary.get("warnings", []):
        lines += ["", f"> **Warning:** {warning}"]
    scans = summary.get("window_scan", {})
    if any(scans.values()):
        lines += ["", "Window check: each exponent refitted with the top of its window moved "
                  "(top: pure power law / with cut-off, points in the window, p-value of the "
                  "pure power law); where a pure power law holds its value does not drift and "
                  "p is not small.", ""]
        for name, (symbol, _) in _NAMES.items():
            rows = scans.get(name) or []
            if rows:
                lines.append(f"* {symbol}: " + ", ".join(
                    f"{row['upper']:.2g}: {row['power_law']:.3f} / {row['cutoff']:.3f} "
                    f"({row['points']}, p = {row['p_value']:.2g})" for row in rows))
    if "by_size" in summary:
        lines += _sizes_section(summary, figures)
    lines += _stress_section(summary)
    if "walls" in summary:
        lines += _walls_section(summary["walls"], figures["walls"])
    lines += ["", "## Distributions", "",
              f"![forces]({figures['forces'].name})", "",
              f"![gaps]({figures['gaps'].name})", "",
              f"![contact numbers]({figures['contacts'].name})", ""]
    if histories:
        lines += ["## Error against wall time, per run", ""]
        lines += [f"![run {k}]({path.parent.name}/{path.name})" for k, path in
                  enumerate(histories)]
        lines.append("")
    return "\n".join(lines)


def _interval(entry: dict | None) -> str:
    """"value [low, high]" of a {"value", "interval"} entry, "—" for None."""
    if entry is None:
        return "—"
    low, high = entry["interval"]
    return f"{_fmt(entry['value'], 3)} [{_fmt(low, 3)}, {_fmt(high, 3)}]"


def _sizes_section(summary: dict, figures: dict[str, Path]) -> list[str]:
    """The "Sizes" section: each exponent per N and extrapolated, the form of the
    extrapolation, the gap cut-off and the two figures."""
    lines = ["", "## Sizes", "",
             "The exponents of the packings of each size N (same windows and models as "
             "above), and their limit N → ∞ (`calippso.analysis.finite_size_analysis`).", "",
             "| N | packings | " + " | ".join(symbol for symbol, _ in _NAMES.values()) + " |",
             "|---|---|" + "---|" * len(_NAMES)]
    for n, row in summary["by_size"].items():
        lines.append(f"| {n} | {row['packings']} | "
                     + " | ".join(_interval(row.get(name)) for name in _NAMES) + " |")
    extrapolated = summary["extrapolated"]
    lines.append("| N → ∞ | | " + " | ".join(_interval(extrapolated.get(name))
                                              for name in _NAMES) + " |")
    lines.append("| literature | | " + " | ".join(
        f"{summary['reference_exponents'][name]:g}" for name in _NAMES) + " |")
    lines += ["", "Extrapolation: "]
    for name, (symbol, _) in _NAMES.items():
        e = extrapolated.get(name)
        if e is None:
            reason = summary["extrapolation_errors"].get(name, "not extrapolated")
            lines.append(f"* {symbol}: not extrapolated: {reason}")
            continue
        omega = "" if _fmt(e["omega"]) == "—" else f", ω = {e['omega']:.3g}"
        p_value = "" if _fmt(e["p_value"]) == "—" else f", χ² p = {e['p_value']:.2g}"
        lines.append(f"* {symbol}: form {e['form']}{omega}{p_value} ({e['reason']})")
    cutoff = summary["gap_cutoff"]
    lines += ["", "Gap cut-off: the geometric mean of each packing's smallest gap, h_min(N) = "
              + ", ".join(f"{h:.3g} (N = {n})" for n, h in zip(cutoff["sizes"],
                                                                cutoff["h_min"]))
              + f"; h_min ~ N^{_fmt(cutoff['slope'], 3)}, so γ = {_fmt(cutoff['gamma'], 3)} "
              f"[{_fmt(cutoff['gamma_interval'][0], 3)}, {_fmt(cutoff['gamma_interval'][1], 3)}]"
              " (h_min ~ N^(−1/(1−γ))).", "",
              f"![exponents against N]({figures['exponents_vs_n'].name})", "",
              f"![gap distributions across sizes]({figures['gaps_collapse'].name})"]
    return lines


def _stress_section(summary: dict) -> list[str]:
    """The "Box, stress and jamming category" section: the count of runs per category,
    then one row per run (box, category, pressure, stress anisotropy, stress tensor)."""
    counts = ", ".join(f"{name}: {count}" for name, count in summary["categories"].items())
    lines = ["", "## Box, stress and jamming category", "",
             f"Jamming categories (local, collective, strict; `calippso.jamming_category`): "
             f"{counts}. Contact stress Σ f |r| n nᵀ / V with forces of mean 1; the "
             "anisotropy is max |stress − p I| / p (zero at a strictly jammed point).", "",
             "| run | box | category | pressure | stress anisotropy | stress |",
             "|---|---|---|---|---|---|"]
    for k, run in enumerate(summary["runs"]):
        stress = ("—" if run["stress"] is None else
                  "[" + "; ".join(" ".join(f"{value:.4g}" for value in row)
                                  for row in run["stress"]) + "]")
        anisotropy = run["stress_anisotropy"]
        lines.append(f"| {k} | {run['box']} | {run['category'] or 'not tested'} | "
                     f"{_fmt(run['pressure'], 6)} | "
                     f"{'—' if anisotropy is None else f'{anisotropy:.1e}'} | {stress} |")
    return lines


def _walls_section(walls: dict, figure: Path) -> list[str]:
    """The "Walls" section: wall-force statistics, loads and pressures, the figure."""
    forces = walls["wall_forces"]
    lines = ["", "## Walls", "",
             "Wall contacts are kept apart: the force distributions and exponents below hold "
             "the particle–particle forces only. Wall forces in units of the mean "
             "particle–particle force of their packing.", "",
             "| wall forces | count | mean | median | min | max |", "|---|---|---|---|---|---|",
             f"| all walls | {forces['count']} | {_fmt(forces['mean'])} | "
             f"{_fmt(forces['median'])} | {_fmt(forces['min'])} | {_fmt(forces['max'])} |"]
    if walls["loads"]:
        lines += ["", "| packing | wall | contacts | load | pressure |", "|---|---|---|---|---|"]
        lines += [f"| {row['packing']} | {row['wall']} | {row['contacts']} | {_fmt(row['load'])} "
                  f"| {_fmt(row['pressure'])} |" for row in walls["loads"]]
    lines += ["", "Layering: the local packing fraction against the distance from the nearest "
              "wall (volume fraction of the spheres in shells parallel to the wall; it tends to "
              "the bulk value far from the wall).", "", f"![walls]({figure.name})"]
    return lines
