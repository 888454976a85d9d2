"""Extended XYZ (ASE, OVITO): a packing in d = 2 or 3, one particle per line.

Layout written::

    N
    Lattice="Lx 0 0 0 Ly 0 0 0 Lz" Properties=species:S:1:pos:R:3:diameter:R:1 pbc="T T T" dimension=3
    X x y z sigma
    ...

Positions are wrapped into [0, L) and written with 17 significant digits, so a round trip is
exact. In d = 2 the z column is 0, ``pbc="T T F"``, ``dimension=2`` and the third lattice
vector has the length of the largest diameter (viewers need one). A `JammingResult` adds the
columns ``rattler:L:1`` (T for rattlers) and ``contacts:I:1`` (contacts per particle), which
OVITO can use to colour particles. The reader also accepts OVITO's ``radius`` column instead
of ``diameter``.

Flat walls (`calippso.geometry.boundaries`) are the axes whose ``pbc`` flag is F: ``pbc="T T F"``
with ``dimension=3`` is a box with walls at z = 0 and z = L_z; in d = 2 the third flag is
always F and the first two say which axes are periodic. A cylinder has no ``pbc`` form and
is refused.
"""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np

from ..atomic import atomic_path
from ..geometry.boundaries import PERIODIC, WALLS, Boundaries
from ..geometry.packing import Packing
from .sheared import refuse_sheared

__all__ = ["column_names", "read", "read_rattlers", "write"]

#: The columns of a plain XYZ file (no Properties in the header).
_DEFAULT_PROPERTIES = "species:S:1:pos:R:3"


def write(obj, path: Path) -> Path:
    """Write a `Packing` or `JammingResult` (d ≤ 3) as extended XYZ.

    Raises
    ------
    ValueError
        If d > 3 (extended XYZ holds three coordinates; use .npz or .h5).
    """
    refuse_sheared(getattr(obj, "packing", obj), "extended XYZ")
    packing = getattr(obj, "packing", obj).wrapped()
    if packing.d > 3:
        raise ValueError(
            f"extended XYZ holds d <= 3, this packing has d = {packing.d}: "
            f"write .npz or .h5 instead"
        )
    if packing.boundaries.cylinder_axes:
        raise ValueError(f"extended XYZ cannot hold a cylinder ({packing.boundaries.describe()})"
                         f": write .npz, .h5 or .gsd instead")
    n, d = packing.n, packing.d
    positions = np.zeros((n, 3))
    positions[:, :d] = packing.positions
    sides = np.append(packing.box, packing.diameters.max()) if d == 2 else packing.box
    lattice = " ".join(f"{v:.17g}" for v in np.diag(sides).ravel())
    properties = "species:S:1:pos:R:3:diameter:R:1"
    columns = [np.full(n, "X"), *(positions[:, k] for k in range(3)), packing.diameters]
    if hasattr(obj, "rattlers") and hasattr(obj, "contact_numbers"):
        properties += ":rattler:L:1:contacts:I:1"
        columns += [np.where(obj.rattlers, "T", "F"), obj.contact_numbers]
    pbc = " ".join(["T" if periodic else "F" for periodic in packing.periodic]
                   + ([] if d == 3 else ["F"]))
    header = f'Lattice="{lattice}" Properties={properties} pbc="{pbc}" dimension={d}'
    body = [" ".join(_format(value) for value in row) for row in zip(*columns)]
    path = Path(path)
    with atomic_path(path) as temporary:
        temporary.write_text("\n".join([str(n), header, *body]) + "\n")
    return path


def _format(value) -> str:
    if isinstance(value, (float, np.floating)):
        return f"{value:.17g}"
    return str(value)


def _header(line: str, path: Path) -> dict[str, str]:
    try:
        tokens = shlex.split(line)
    except ValueError as error:
        raise ValueError(f"{path}, line 2: unreadable extended XYZ header ({error})") from None
    fields = {}
    for token in tokens:
        key, _, value = token.partition("=")
        fields[key.lower()] = value
    return fields


def _columns(properties: str, path: Path) -> dict[str, tuple[int, int]]:
    parts = properties.split(":")
    if len(parts) % 3:
        raise ValueError(
            f"{path}, line 2: Properties={properties!r} is not name:type:count triples"
        )
    columns, start = {}, 0
    for name, count in zip(parts[::3], parts[2::3]):
        columns[name.lower()] = (start, int(count))
        start += int(count)
    return columns


def read(path: Path) -> Packing:
    """Read the first frame of an extended XYZ file into a `Packing`.

    The box comes from a diagonal ``Lattice``; diameters from a ``diameter`` column (or twice
    a ``radius`` column); d from ``dimension=`` or, failing that, 2 when ``pbc`` is
    ``"T T F"`` and 3 otherwise.

    Raises
    ------
    ValueError
        If the file is not extended XYZ, has no lattice, a non-rectangular one, or no
        diameter/radius column.
    """
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file (expected extended XYZ)") from None
    try:
        n = int(lines[0].strip())
    except (IndexError, ValueError):
        raise ValueError(f"{path}, line 1: expected the number of particles") from None
    if len(lines) < n + 2:
        raise ValueError(
            f"{path}: truncated, {max(len(lines) - 2, 0)} particle lines where N = {n}"
        )
    fields = _header(lines[1], path)
    if "lattice" not in fields:
        raise ValueError(f"{path}, line 2: no Lattice= (a periodic box is required)")
    try:
        lattice = np.array(fields["lattice"].split(), dtype=float).reshape(3, 3)
    except ValueError:
        raise ValueError(f"{path}, line 2: Lattice= needs 9 numbers") from None
    if np.any(lattice[~np.eye(3, dtype=bool)] != 0):
        raise ValueError(f"{path}, line 2: only rectangular (diagonal) lattices are supported")
    pbc = fields.get("pbc", "T T T").upper().split()
    d = int(fields.get("dimension", 2 if pbc[2:3] == ["F"] else 3))
    if d not in (2, 3):
        raise ValueError(f"{path}, line 2: dimension={d}, expected 2 or 3")
    columns = _columns(fields.get("properties", _DEFAULT_PROPERTIES), path)
    if "pos" not in columns:
        raise ValueError(f"{path}, line 2: no pos column in Properties")
    size = "diameter" if "diameter" in columns else "radius" if "radius" in columns else None
    if size is None:
        raise ValueError(f"{path}, line 2: no diameter or radius column in Properties")
    rows = [line.split() for line in lines[2 : 2 + n]]
    width = sum(count for _, count in columns.values())
    short = next((k for k, row in enumerate(rows) if len(row) < width), None)
    if short is not None:
        raise ValueError(
            f"{path}, line {short + 3}: {len(rows[short])} fields where Properties needs {width}"
        )

    def column(name: str) -> np.ndarray:
        start, count = columns[name]
        return np.array([row[start : start + count] for row in rows], dtype=float)

    try:
        positions = column("pos")[:, :d]
        diameters = column(size)[:, 0] * (2.0 if size == "radius" else 1.0)
    except ValueError as error:
        raise ValueError(f"{path}: non-numeric position or size ({error})") from None
    if any(flag not in ("T", "F") for flag in pbc[:d]) or len(pbc) < d:
        raise ValueError(f"{path}, line 2: pbc={fields['pbc']!r} needs T or F for each of the "
                         f"{d} axes")
    boundaries = Boundaries(tuple(PERIODIC if flag == "T" else WALLS for flag in pbc[:d]))
    try:
        return Packing(positions, diameters, np.diag(lattice)[:d].copy(), boundaries)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def column_names(path: Path) -> set[str]:
    """The names (lower case) of the columns an extended XYZ file declares in Properties.

    Raises
    ------
    ValueError
        If the file has no header line or the header is not extended XYZ.
    """
    path = Path(path)
    with open(path, encoding="utf-8", errors="replace") as stream:
        stream.readline()
        header = stream.readline()
    if not header:
        raise ValueError(f"{path}, line 2: no extended XYZ header")
    fields = _header(header, path)
    return set(_columns(fields.get("properties", _DEFAULT_PROPERTIES), path))


def read_rattlers(path: Path) -> np.ndarray | None:
    """The ``rattler`` column (T/F) written with a `JammingResult`, or None without one."""
    path = Path(path)
    lines = path.read_text().splitlines()
    columns = _columns(_header(lines[1], path).get("properties", _DEFAULT_PROPERTIES), path)
    if "rattler" not in columns:
        return None
    start, _ = columns["rattler"]
    n = int(lines[0].strip())
    return np.array([line.split()[start].upper() in ("T", "TRUE", "1")
                     for line in lines[2:2 + n]])
