"""``calippso report``: analyse jammed results and write one pooled report."""

from __future__ import annotations

import json
from pathlib import Path

import click

from .common import Container, container_options, naming, output_options, with_container


@click.command()
@click.argument(
    "results",
    metavar="RESULT...",
    nargs=-1,
    required=True,
    type=click.Path(path_type=Path),
)
@click.option(
    "-o",
    "--output",
    "output",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the report.",
)
@click.option(
    "--model",
    type=click.Choice(["auto", "power_law", "cutoff"]),
    default=None,
    help="Model of every exponent fit: pure power law, power law with exponential cut-off, or "
    "the one a likelihood-ratio test picks (default: power_law for gaps, auto for forces; "
    "docs/analysis.md).",
)
@click.option(
    "--rule",
    type=click.Choice(["bucklers", "weakest", "response"]),
    default="bucklers",
    show_default=True,
    help="Which forces are localised: every force on a buckler, only each buckler's weakest "
    "force, or the contacts whose opening moves one particle (isostatic packings only; "
    "docs/analysis.md).",
)
@click.option(
    "--correction",
    type=click.Choice(["auto", "constant", "inverse_n", "power"]),
    default="auto",
    show_default=True,
    help="Packings of several sizes: the finite-size correction of the extrapolation to "
    "N -> infinity (auto: x_inf + a N^-omega with omega fitted from four sizes on, 1/N with "
    "fewer; docs/analysis.md).",
)
@click.option(
    "--omega",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Fix omega of the correction x_inf + a N^-omega.",
)
@click.option(
    "--gap-floor",
    type=click.Choice(["rank", "cutoff"]),
    default="rank",
    show_default=True,
    help="Packings of several sizes: start the gamma window of each size at the 10th smallest "
    "gap (rank) or at that size's cut-off h_min(N), above the depletion of the smallest gaps.",
)
@container_options
@output_options
def report(results, output, model, rule, correction, omega, gap_floor, container, out):
    """Analyse jammed results (.npz/.h5 files, or folders of them such as an ensemble's) and
    write one pooled report to a folder.

    Packings of several sizes are also grouped by N: each exponent per size and extrapolated
    to N -> infinity (exponents_vs_n.png, gaps_collapse.png, "by_size" and "extrapolated"
    in summary.json).

    A packing with walls adds the wall forces (apart from the particle forces), the loads and
    pressures on the walls and the layering profile; --walls/--cylinder set the boundaries of
    periodic results (for the layering profile; they carry no wall forces).
    """
    files, loaded, skipped = read_results(results)
    loaded = [_with_container(result, container, path) for result, path in zip(loaded, files)]
    page = make_report(loaded, output, model=model, rule=rule, correction=correction,
                       omega=omega, gap_floor=gap_floor)
    warnings = json.loads((page.parent / "summary.json").read_text()).get("warnings", [])
    record = {"command": "report", "results": [str(p) for p in files],
              "skipped": [str(p) for p in skipped], "report": str(page), "warnings": warnings}
    lines = [f"report of {len(loaded)} packing(s) -> {page}"]
    if skipped:
        lines.append(f"skipped {len(skipped)} file(s) that hold no result: "
                     + ", ".join(p.name for p in skipped))
    lines += [f"warning: {warning}" for warning in warnings]
    return record, "\n".join(lines)


#: Extensions of the result files `report` looks for in a folder.
RESULT_SUFFIXES = (".npz", ".h5", ".hdf5")


def read_results(paths: tuple[Path, ...]) -> tuple[list[Path], list, list[Path]]:
    """Read the results named by `paths`: the files read, their results, the files skipped.

    A file must be a result file. A folder (such as one made by ``calippso ensemble``) gives
    its `RESULT_SUFFIXES` files, sorted by name; those that hold no result (the state files
    of an unfinished run) are skipped.

    Raises
    ------
    ValueError
        A file that is not a result file, or a folder without one (the message names it).
    """
    from ..io import read_result

    files, results, skipped = [], [], []
    for path in paths:
        if not path.is_dir():
            with naming(path):
                results.append(read_result(path))
            files.append(path)
            continue
        before = len(results)
        for candidate in sorted(p for p in path.iterdir()
                                if p.is_file() and p.suffix.lower() in RESULT_SUFFIXES):
            try:
                results.append(read_result(candidate))
            except ValueError:
                skipped.append(candidate)
            else:
                files.append(candidate)
        if len(results) == before:
            raise ValueError(f"{path}: a folder with no result file "
                             f"({', '.join(RESULT_SUFFIXES)}) in it")
    return files, results, skipped


def _with_container(result, container: Container | None, path: Path):
    """`result` with its packing's boundaries set by `container` (`common.with_container`)."""
    import dataclasses

    packing = with_container(result.packing, container, path)
    return result if packing is result.packing else dataclasses.replace(result, packing=packing)


def make_report(results: list, folder: Path, **options) -> Path:
    """`calippso.report`, with a clear error where the reporting package is not installed."""
    import calippso

    try:
        build = calippso.report
    except AttributeError:
        raise click.ClickException("this calippso has no report module (calippso.report)") from None
    return Path(build(results, folder, **options))
