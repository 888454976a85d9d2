"""GSD (HOOMD-blue, OVITO) via the `gsd` package: one frame, d = 2 or 3.

The HOOMD schema stores positions and diameters as float32, centred on the origin
([−L/2, L/2)), which is what viewers read. float32 would move jammed particles by ~1e-7 σ and
create overlaps, so the exact float64 values are stored too, as logged quantities
``calippso/positions`` (wrapped into [0, L)), ``calippso/diameters`` and ``calippso/box``;
the reader prefers them and falls back to the float32 schema data for files written by other
programs. A `JammingResult` also logs ``calippso/geometry/rattlers`` and ``calippso/geometry/contacts``
(contacts per particle) and sets the particle type to "stable" or "rattler". A box with walls
logs ``calippso/geometry/boundaries``, one code per axis (the index of its kind in
`calippso.geometry.boundaries.KINDS`); a file without it is periodic.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..atomic import atomic_path
from ..geometry.boundaries import KINDS, Boundaries
from ..geometry.packing import Packing
from .sheared import refuse_sheared

__all__ = ["read", "write"]


def _gsd_hoomd():
    try:
        import gsd.hoomd
    except ImportError:
        raise ValueError(
            "GSD files need the gsd package: pip install 'calippso[formats]'"
        ) from None
    return gsd.hoomd


def write(obj, path: Path) -> Path:
    """Write a `Packing` or `JammingResult` (d ≤ 3) as a one-frame GSD file.

    Raises
    ------
    ValueError
        If d > 3 (HOOMD boxes are 2D or 3D; use .npz or .h5), or gsd is not installed.
    """
    hoomd = _gsd_hoomd()
    refuse_sheared(getattr(obj, "packing", obj), "GSD")
    packing = getattr(obj, "packing", obj).wrapped()
    if packing.d > 3:
        raise ValueError(
            f"GSD holds d <= 3, this packing has d = {packing.d}: write .npz or .h5 instead"
        )
    n, d = packing.n, packing.d
    frame = hoomd.Frame()
    frame.configuration.dimensions = d
    frame.configuration.box = [*packing.box, *([0.0] if d == 2 else []), 0.0, 0.0, 0.0]
    centred = np.zeros((n, 3))
    centred[:, :d] = packing.positions - 0.5 * packing.box
    frame.particles.N = n
    frame.particles.position = centred.astype(np.float32)
    frame.particles.diameter = packing.diameters.astype(np.float32)
    frame.log = {
        "calippso/positions": packing.positions,
        "calippso/diameters": packing.diameters,
        "calippso/box": packing.box,
    }
    if not packing.boundaries.is_periodic:
        frame.log["calippso/geometry/boundaries"] = np.array(
            [KINDS.index(kind) for kind in packing.boundaries.kinds], dtype=np.uint8)
    if hasattr(obj, "rattlers") and hasattr(obj, "contact_numbers"):
        frame.particles.types = ["stable", "rattler"]
        frame.particles.typeid = obj.rattlers.astype(np.uint32)
        frame.log["calippso/geometry/rattlers"] = obj.rattlers.astype(np.uint8)
        frame.log["calippso/geometry/contacts"] = obj.contact_numbers
    path = Path(path)
    with atomic_path(path) as temporary:
        with hoomd.open(temporary, mode="w") as trajectory:
            trajectory.append(frame)
    return path


def read(path: Path) -> Packing:
    """Read the last frame of a GSD file into a `Packing` (exact float64 data when present).

    Raises
    ------
    ValueError
        If the file is not GSD, is empty, has a tilted box, or gsd is not installed.
    """
    hoomd = _gsd_hoomd()
    try:
        with hoomd.open(path, mode="r") as trajectory:
            if len(trajectory) == 0:
                raise ValueError(f"{path}: the GSD file has no frame")
            frame = trajectory[-1]
    except (OSError, RuntimeError) as error:
        raise ValueError(f"{path}: not a readable GSD file ({error})") from None
    log = frame.log
    if "calippso/positions" in log:
        boundaries = (Boundaries(tuple(KINDS[int(code)] for code in log["calippso/geometry/boundaries"]))
                      if "calippso/geometry/boundaries" in log else None)
        try:
            return Packing(log["calippso/positions"], log["calippso/diameters"],
                           log["calippso/box"], boundaries)
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None
    box = np.asarray(frame.configuration.box, dtype=np.float64)
    if np.any(box[3:] != 0):
        raise ValueError(
            f"{path}: tilted (triclinic) boxes are not supported, tilts {box[3:].tolist()}"
        )
    d = int(frame.configuration.dimensions)
    sides = box[:d]
    positions = np.asarray(frame.particles.position, dtype=np.float64)[:, :d] + 0.5 * sides
    return Packing(positions, np.asarray(frame.particles.diameter, dtype=np.float64), sides)
