"""``calippso ensemble``: many generate → jam → analyse runs, on local processes or Dask."""

from __future__ import annotations

from pathlib import Path

import click

from ..protocols import PROTOCOLS
from .common import (diameter_options, final_growth_rate_option, output_options, positive,
                     solver_option)


@click.command()
@click.option(
    "--protocol",
    type=click.Choice(PROTOCOLS),
    default="ls",
    show_default=True,
    help="How each start is made (poisson: random, low density).",
)
@diameter_options
@click.option(
    "--pressure",
    type=positive(float),
    default=1e5,
    show_default=True,
    help="LS target reduced pressure.",
)
@final_growth_rate_option
@click.option(
    "--precompress",
    type=positive(float),
    default=None,
    help="Compress every start by Lubachevsky-Stillinger MD to this reduced pressure before "
    "jamming it (for loose fb and poisson starts), e.g. 1e5.",
)
@click.option(
    "--packings",
    type=positive(int),
    default=4,
    show_default=True,
    help="Number of packings (seeds SEED, SEED+1, ...).",
)
@solver_option
@click.option(
    "-o",
    "--output",
    "output",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the packings and summary.csv.",
)
@click.option(
    "--workers",
    type=positive(int),
    default=None,
    help="Local worker processes (default: the number of cores).",
)
@click.option(
    "--threads",
    type=positive(int),
    default=None,
    help="Threads of each local worker (Numba, BLAS, MKL); default: the cores shared out "
    "among the workers.",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    default=None,
    help="Run on a Dask cluster (e.g. tcp://host:8786) instead of local processes; "
    "this process writes the files.",
)
@output_options
def ensemble(
    protocol,
    n,
    d,
    distribution,
    ratio,
    std,
    seed,
    pressure,
    final_growth_rate,
    precompress,
    packings,
    solver,
    output,
    workers,
    threads,
    scheduler,
    out,
):
    """Many independent generate → jam → analyse runs; resumes a folder made with the same
    parameters (a rerun with other parameters is refused)."""
    from .. import ensemble as runs

    spec = runs.EnsembleSpec(
        protocol=protocol,
        n=n,
        d=d,
        distribution=distribution,
        ratio=ratio,
        std=std,
        pressure=pressure,
        final_growth_rate=final_growth_rate,
        precompress=precompress,
        solver=solver,
    )
    seeds = range(seed, seed + packings)
    if scheduler is not None:
        try:
            table = runs.run_on_scheduler(spec, packings, seeds=seeds, out_dir=output,
                                          address=scheduler, progress=out.progress)
        except ImportError:  # dask.distributed missing
            raise click.UsageError(
                "--scheduler needs dask.distributed: pip install 'calippso[ensemble]'"
            ) from None
    else:
        table = runs.run(
            spec, packings, seeds=seeds, out_dir=output, workers=workers, threads=threads,
            progress=out.progress
        )
    failed = [row for row in table if row["state"] == "failed"]
    record = {
        "command": "ensemble",
        "out_dir": str(output),
        "summary": str(output / runs.SUMMARY),
        "packings": len(table),
        "failed": len(failed),
        "rows": table,
    }
    text = (
        f"{len(table) - len(failed)} of {len(table)} packings done, summary in "
        f"{output / runs.SUMMARY}"
    )
    if failed:
        text += "\n" + "\n".join(f"  seed {row['seed']} failed: {row['error']}" for row in failed)
    return record, text
