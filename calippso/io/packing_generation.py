"""PackingGeneration (Baranau's C++ code): `packing.xyzd` + `packing.nfo` + `generation.conf`.

`packing.xyzd` holds little-endian float64 (x, y, z, d) per particle, d the nominal diameter.
The true diameters are d · ((1 − final porosity)/(1 − theoretical porosity))^(1/3), with the
porosities from `packing.nfo`. The box side comes from "Packing size:" in `generation.conf`,
and its "Boundaries mode:" says the container (a file without the line is periodic):

* 1, periodic in x, y and z;
* 2, a cylinder: a circle of diameter X = Y inscribed in the box in xy, centred at
  (X/2, Y/2), periodic in z (`calippso.geometry.boundaries.Boundaries.cylinder`);
* 3, a rectangle in xy: flat walls at x = 0, X and y = 0, Y, periodic in z
  (`calippso.geometry.boundaries.Boundaries.walls`).

The diameters are rescaled as in mode 1 in every mode (the rescale is a ratio of two
porosities of the same container). Mode 4 (a trapezoid) is refused until calippso can jam
it. `write` writes modes 1, 2 and 3.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..geometry.boundaries import Boundaries
from ..geometry.packing import Packing
from .sheared import refuse_sheared

#: PackingGeneration's "Boundaries mode:" values and what each means.
BOUNDARIES_MODES = {1: "periodic in x, y and z",
                    2: "periodic in z inside a circle in xy",
                    3: "periodic in z inside a rectangle in xy",
                    4: "periodic in z inside a trapezoid in xy"}
#: The modes calippso reads.
PERIODIC_MODE = 1
CYLINDER_MODE = 2
RECTANGLE_MODE = 3
#: Axes with walls in the rectangle mode, and of the circle in the cylinder mode (x and y).
RECTANGLE_AXES = (0, 1)
CYLINDER_AXES = (0, 1)


def _field(text: str, label: str, path: Path) -> list[float]:
    match = re.search(rf"{label}\s*:\s*([^\n(]+)", text)
    if not match:
        raise ValueError(f"{path}: no '{label}:' line")
    try:
        return [float(v) for v in match.group(1).split()]
    except ValueError:
        raise ValueError(f"{path}: '{label}:' is not numeric: {match.group(1)!r}") from None


def _boundaries_mode(text: str, path: Path) -> int:
    """The "Boundaries mode:" of `generation.conf` (text `text`): `PERIODIC_MODE` when the
    line is absent; ValueError naming `path` and the mode unless calippso reads it."""
    match = re.search(r"Boundaries mode\s*:\s*([^\n]*)", text)
    if not match:
        return PERIODIC_MODE
    value = match.group(1).strip()
    try:
        mode = int(value)
    except ValueError:
        raise ValueError(f"{path}: 'Boundaries mode:' is not an integer: {value!r}") from None
    if mode not in BOUNDARIES_MODES:
        raise ValueError(f"{path}: unknown boundaries mode {mode}; PackingGeneration's modes "
                         f"are {', '.join(map(str, BOUNDARIES_MODES))}")
    if mode not in (PERIODIC_MODE, CYLINDER_MODE, RECTANGLE_MODE):
        raise ValueError(f"{path}: boundaries mode {mode} ({BOUNDARIES_MODES[mode]}) is not "
                         f"supported; calippso reads periodic packings (mode {PERIODIC_MODE}), "
                         f"cylinders (mode {CYLINDER_MODE}) and rectangles "
                         f"(mode {RECTANGLE_MODE})")
    return mode


def read(path: Path) -> Packing:
    """Read a PackingGeneration folder (or its `.xyzd` file with the two text files beside it)."""
    path = Path(path)
    folder = path if path.is_dir() else path.parent
    xyzd = folder / "packing.xyzd" if path.is_dir() else path
    conf, nfo = folder / "generation.conf", folder / "packing.nfo"
    for needed in (conf, nfo):
        if not needed.exists():
            raise ValueError(f"{xyzd}: {needed.name} is missing beside it (needed for the "
                             f"{'box size' if needed is conf else 'diameter rescaling'})")
    conf_text = conf.read_text()
    mode = _boundaries_mode(conf_text, conf)
    raw = np.fromfile(xyzd, dtype="<f8")
    if raw.size == 0 or raw.size % 4:
        raise ValueError(f"{xyzd}: {raw.size * 8} bytes is not a whole number of (x, y, z, d) records")
    records = raw.reshape(-1, 4)
    box = np.array(_field(conf_text, "Packing size", conf))
    count = _field(conf_text, "Particles count", conf)[0]
    if int(count) != records.shape[0]:
        raise ValueError(f"{xyzd}: {records.shape[0]} particles but generation.conf says {int(count)}")
    nfo_text = nfo.read_text()
    theoretical = _field(nfo_text, "Theoretical Porosity", nfo)[0]
    final = _field(nfo_text, "Final Porosity", nfo)[0]
    scale = ((1.0 - final) / (1.0 - theoretical)) ** (1.0 / 3.0)
    boundaries = {PERIODIC_MODE: None, CYLINDER_MODE: Boundaries.cylinder(3, CYLINDER_AXES),
                  RECTANGLE_MODE: Boundaries.walls(3, RECTANGLE_AXES)}[mode]
    try:
        return Packing(records[:, :3], records[:, 3] * scale, box, boundaries)
    except ValueError as error:
        raise ValueError(f"{xyzd}: {error}") from None


def write(packing: Packing, path: Path) -> Path:
    """Write `packing.xyzd` with true diameters, plus a consistent `packing.nfo` and `generation.conf`.

    The `.nfo` states equal final and theoretical porosity, so reading back applies no rescale.
    The conf's "Boundaries mode:" is 1 for a periodic packing, 2 for a cylinder in xy and 3
    for walls in x and y, z periodic in both; other containers are refused.
    """
    refuse_sheared(packing, "PackingGeneration")
    if packing.d != 3:
        raise ValueError(f"PackingGeneration files hold d = 3 only, this packing has d = {packing.d}")
    if packing.boundaries.is_periodic:
        mode = PERIODIC_MODE
    elif packing.boundaries == Boundaries.walls(3, RECTANGLE_AXES):
        mode = RECTANGLE_MODE
    elif packing.boundaries == Boundaries.cylinder(3, CYLINDER_AXES):
        mode = CYLINDER_MODE
    else:
        raise ValueError(f"PackingGeneration holds periodic boxes, cylinders in x, y and "
                         f"rectangles (walls in x, y), periodic in z, not "
                         f"{packing.boundaries.describe()}")
    path = Path(path)
    folder = path if path.suffix != ".xyzd" else path.parent
    folder.mkdir(parents=True, exist_ok=True)
    xyzd = folder / "packing.xyzd" if path.suffix != ".xyzd" else path
    records = np.column_stack([packing.wrapped().positions, packing.diameters]).astype("<f8")
    records.tofile(xyzd)
    porosity = 1.0 - packing.phi
    (folder / "packing.nfo").write_text(
        f"N: {packing.n}\n Theoretical Porosity: {porosity:.17g}\nFinal Porosity: {porosity:.17g}\n")
    (folder / "generation.conf").write_text(
        f"Particles count: {packing.n}\nPacking size: "
        + " ".join(f"{v:.17g}" for v in packing.box) + f"\nBoundaries mode: {mode}\n")
    return xyzd
