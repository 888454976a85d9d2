"""``calippso render``: draw a packing of spheres, disks or spherocylinders as a PNG."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import TYPE_CHECKING

import click

from .common import Container, container_options, naming, output_options, output_path
from .common import with_container

if TYPE_CHECKING:
    import numpy as np

    from ..geometry.packing import Packing


@click.command()
@click.argument("source", metavar="IN", type=click.Path(exists=True, path_type=Path))
@output_path()
@click.option(
    "--backend",
    type=click.Choice(["auto", "povray", "matplotlib"]),
    default="auto",
    show_default=True,
    help="POV-Ray (ray-traced, d = 3; 'auto' uses it when installed) or matplotlib.",
)
@click.option(
    "--colour-by",
    type=click.Choice(["orientation", "species"]),
    default=None,
    help="Spherocylinders: by axis direction (|u_x|, |u_y|, |u_z| as RGB; the default) or by "
    "aspect ratio. Spheres are coloured by diameter (species), rattlers grey.",
)
@click.option("--size", type=click.IntRange(min=64), default=900, show_default=True,
              help="Width and height in pixels.")
@container_options
@output_options
def render(source, output, backend, colour_by, size, container, out):
    """Draw a packing as a PNG with a title, a colour key and the box outline.

    IN is a spherocylinder packing (extended XYZ from `generate spherocylinders`) or a
    packing of spheres (d = 3) or disks (d = 2) in any readable format; a jammed result
    (.npz, .h5, or .xyz written from one) shows its rattlers in grey. The walls of a packing
    that has them (or that --walls/--cylinder give it) are drawn.
    """
    if output.suffix.lower() != ".png":
        raise click.BadParameter("the picture is a PNG: use a .png name", param_hint="'-o'")
    with naming(source):
        if _holds_spherocylinders(source):
            if container is not None:
                raise click.BadParameter("spherocylinder pictures have no walls",
                                         param_hint=f"'{container.option.split()[0]}'")
            return _render_spherocylinders(source, output, backend, colour_by or "orientation",
                                           size)
        if colour_by == "orientation":
            raise click.BadParameter("spheres have no orientation: leave it out or use "
                                     "'species'", param_hint="'--colour-by'")
        return _render_spheres(source, output, backend, size, container)


def _holds_spherocylinders(path: Path) -> bool:
    """Whether `path` is extended XYZ with the axis and length columns of spherocylinders."""
    from ..io import SUFFIXES, extxyz

    return (path.is_file() and SUFFIXES.get(path.suffix.lower()) == "extxyz"
            and {"axis", "length"} <= extxyz.column_names(path))


def _render_spherocylinders(source: Path, output: Path, backend: str, colour_by: str,
                            size: int) -> tuple[dict, str]:
    from generators import spherocylinders

    packing = spherocylinders.read_xyz(source)
    written = spherocylinders.render(packing, output, backend=backend, colour_by=colour_by,
                                     size=size)
    record = {"command": "render", "input": str(source), "output": str(written),
              "particles": "spherocylinders", "n": packing.n, "phi": packing.phi,
              "nematic_order": packing.nematic_order()}
    return record, f"{packing.n} spherocylinders, phi = {packing.phi:.6f}: {source} -> {written}"


def _render_spheres(source: Path, output: Path, backend: str, size: int,
                    container: Container | None) -> tuple[dict, str]:
    from ..reporting.render import render_spheres

    packing, rattlers = _spheres_and_rattlers(source)
    packing = with_container(packing, container, source)
    written = render_spheres(packing, output, rattlers=rattlers, backend=backend, size=size)
    kind = "disks" if packing.d == 2 else "spheres"
    record = {"command": "render", "input": str(source), "output": str(written),
              "particles": kind, "n": packing.n, "d": packing.d, "phi": packing.phi,
              "rattlers": None if rattlers is None else int(rattlers.sum()),
              "boundaries": str(packing.boundaries)}
    return record, f"{packing.n} {kind}, phi = {packing.phi:.6f}: {source} -> {written}"


def _spheres_and_rattlers(source: Path) -> tuple[Packing, np.ndarray | None]:
    """The packing in `source`, and its rattlers where the file holds a jammed result."""
    import calippso
    from ..io import SUFFIXES, extxyz, read_result

    kind = SUFFIXES.get(source.suffix.lower())
    if kind in ("npz", "hdf5") and source.is_file():
        with contextlib.suppress(ValueError):  # not a result file: read it as a packing
            result = read_result(source)
            return result.packing, result.rattlers
    packing = calippso.read(source)
    return packing, extxyz.read_rattlers(source) if kind == "extxyz" else None
