"""Extended XYZ with orientations, for OVITO (and ASE): write and read back.

Columns: ``species:S:1 pos:R:3 orientation:R:4 aspherical_shape:R:3 axis:R:3 diameter:R:1
length:R:1``. ``orientation`` is the unit quaternion (x, y, z, w) (OVITO's order) turning the
local z axis onto the particle axis; ``aspherical_shape`` is (d/2, d/2, l), which OVITO's
"Spherocylinder" shape reads as (radius, –, cylinder length along local z). Map these columns
to OVITO's Orientation and Aspherical Shape properties if it does not do so itself, and pick the
spherocylinder shape in the Particles visual element. ``axis``, ``diameter`` and ``length``
repeat the same information plainly (``read_xyz`` uses them).
"""

from __future__ import annotations

import shlex
from os import PathLike
from pathlib import Path

import numpy as np

from .packing import SpherocylinderPacking

__all__ = ["write_xyz", "read_xyz", "axis_quaternions"]

_PROPERTIES = ("species:S:1:pos:R:3:orientation:R:4:aspherical_shape:R:3:axis:R:3:"
               "diameter:R:1:length:R:1")


def axis_quaternions(axes: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of the rotations turning ẑ onto each axis.

    Parameters
    ----------
    axes : ndarray, shape (N, 3)
        Unit vectors.

    Returns
    -------
    ndarray, shape (N, 4)
        The shortest-arc rotation: w ∝ 1 + u_z, (x, y, z) ∝ ẑ × u; for u = −ẑ, a half turn
        about x.
    """
    axes = np.asarray(axes, dtype=np.float64)
    quaternions = np.column_stack([-axes[:, 1], axes[:, 0], np.zeros(len(axes)), 1.0 + axes[:, 2]])
    norms = np.linalg.norm(quaternions, axis=1)
    flipped = norms < 1e-12
    quaternions[flipped] = [1.0, 0.0, 0.0, 0.0]
    norms[flipped] = 1.0
    return quaternions / norms[:, None]


def _species_names(packing: SpherocylinderPacking) -> np.ndarray:
    shapes = np.round(np.column_stack([packing.diameters, packing.lengths]), 12)
    _, index = np.unique(shapes, axis=0, return_inverse=True)
    letters = np.array([chr(ord("A") + k) if k < 26 else f"T{k}" for k in range(index.max() + 1)])
    return letters[index.ravel()]


def write_xyz(packing: SpherocylinderPacking, path: str | PathLike, *,
              comment: str = "") -> Path:
    """Write a packing as one extended-XYZ frame.

    Parameters
    ----------
    packing : SpherocylinderPacking
    path : str or path-like
        Output file (conventionally ``.xyz``).
    comment : str
        Free text added to the header line as ``comment="..."``.

    Returns
    -------
    Path
        The file written. Species are A, B, … by distinct (diameter, length).
    """
    path = Path(path)
    box = packing.box
    quaternions = axis_quaternions(packing.axes)
    shape = np.column_stack([packing.diameters / 2, packing.diameters / 2, packing.lengths])
    names = _species_names(packing)
    header = (f'Lattice="{float(box[0])!r} 0.0 0.0 0.0 {float(box[1])!r} 0.0 0.0 0.0 {float(box[2])!r}" '
              f'Origin="0.0 0.0 0.0" pbc="T T T" Properties={_PROPERTIES} '
              f"phi={packing.phi!r} nematic_order={packing.nematic_order()!r}")
    if comment:
        header += ' comment="' + comment.replace('"', "'") + '"'
    columns = np.column_stack([packing.positions, quaternions, shape, packing.axes,
                               packing.diameters, packing.lengths])
    with path.open("w", encoding="utf-8") as handle:
        handle.write(f"{packing.n}\n{header}\n")
        for name, row in zip(names, columns):
            handle.write(name + " " + " ".join(repr(float(x)) for x in row) + "\n")
    return path


def read_xyz(path: str | PathLike) -> SpherocylinderPacking:
    """Read a file written by `write_xyz` (first frame).

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    SpherocylinderPacking

    Raises
    ------
    ValueError
        If the header lacks the lattice or one of the columns pos, axis, diameter, length.
    """
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    n = int(lines[0])
    fields = dict(token.split("=", 1) for token in shlex.split(lines[1]) if "=" in token)
    if "Lattice" not in fields or "Properties" not in fields:
        raise ValueError(f"{path}: the header has no Lattice or Properties")
    lattice = np.array(fields["Lattice"].split(), dtype=np.float64).reshape(3, 3)
    spec = fields["Properties"].split(":")
    offsets, start = {}, 0
    for name, _, width in zip(spec[::3], spec[1::3], spec[2::3]):
        offsets[name] = (start, start + int(width))
        start += int(width)
    missing = {"pos", "axis", "diameter", "length"} - set(offsets)
    if missing:
        raise ValueError(f"{path}: columns {sorted(missing)} are missing from Properties")
    rows = [line.split() for line in lines[2:2 + n]]
    table = np.array([row[1:] for row in rows], dtype=np.float64)  # column 0 is the species

    def column(name):
        first, last = offsets[name]
        return table[:, first - 1:last - 1]

    return SpherocylinderPacking(column("pos"), column("axis"), column("diameter")[:, 0],
                                 column("length")[:, 0], np.diag(lattice))
