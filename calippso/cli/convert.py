"""``calippso convert``: convert between file formats."""

from __future__ import annotations

import contextlib
from pathlib import Path

import click

from .common import naming, output_options


@click.command()
@click.argument("source", metavar="IN", type=click.Path(path_type=Path))
@click.argument("target", metavar="OUT", type=click.Path(path_type=Path))
@output_options
def convert(source, target, out):
    """Convert between file formats (by extension); a full result stays full where OUT can hold it.

    Formats: .npz, .h5/.hdf5 (any d); .xyz/.extxyz, .gsd (d ≤ 3); .dat/.txt (Skoge–Donev,
    any d); .xyzd or a PackingGeneration folder (d = 3).
    """
    import calippso
    from ..io import SUFFIXES, read_result

    obj = None
    if SUFFIXES.get(source.suffix.lower()) in ("npz", "hdf5") and source.is_file():
        with contextlib.suppress(ValueError):  # not a result file: read it as a packing
            obj = read_result(source)
    if obj is None:
        with naming(source):
            obj = calippso.read(source)
    with naming(target):
        written = calippso.write(obj, target)
    packing = getattr(obj, "packing", obj)
    kind = "result" if obj is not packing else "packing"
    return (
        {
            "command": "convert",
            "input": str(source),
            "output": str(written),
            "kind": kind,
            "n": packing.n,
            "d": packing.d,
        },
        f"{kind} N = {packing.n}, d = {packing.d}: {source} -> {written}",
    )
