"""Our own `.npz` format: a `Packing` (positions, diameters, box) or a full `JammingResult`."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from ..packing import Packing
from ..atomic import save_npz_atomic


def read(path: Path) -> Packing:
    """Read the packing stored in an `.npz` (a packing file or a result file)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in ("positions", "diameters", "box") if k not in data.files]
            if missing:
                raise ValueError(f"{path}: not a calippso .npz file, missing keys {missing}")
            try:
                return Packing(data["positions"], data["diameters"], data["box"])
            except ValueError as error:
                raise ValueError(f"{path}: {error}") from None
    except (OSError, EOFError, zipfile.BadZipFile) as error:
        raise ValueError(f"{path}: unreadable .npz file ({error})") from None


def write(obj, path: Path) -> Path:
    """Write a `Packing` or `JammingResult` (anything with `to_arrays`) atomically."""
    if hasattr(obj, "save"):
        return obj.save(path)
    arrays = {"positions": obj.positions, "diameters": obj.diameters, "box": obj.box}
    save_npz_atomic(Path(path), arrays)
    return Path(path)
