"""Our own `.npz` format: a `Packing` (positions, diameters, box, and "boundaries" when the
box has walls) or a full `JammingResult`."""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from ..atomic import save_npz_atomic
from ..geometry.packing import Packing, packing_arrays, packing_of

__all__ = ["load_arrays", "read", "write"]

#: First bytes of a zip archive (a local file header, or the end record of an empty one):
#: what `numpy.load` takes for an `.npz` archive.
ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")
#: First bytes of a single numpy array file (`.npy`).
NPY_MAGIC = b"\x93NUMPY"


def load_arrays(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Every array of an `.npz` archive, by key; never unpickles anything.

    Raises
    ------
    ValueError
        One line naming the file when it is not an `.npz` archive (a text file, a single
        `.npy` array), a damaged one, or one holding pickled Python objects.
    """
    path = Path(path)
    with open(path, "rb") as stream:
        head = stream.read(len(NPY_MAGIC))
    if not head.startswith(ZIP_MAGIC):
        why = ("it is empty" if not head else "it is a single numpy array, a .npy file"
               if head.startswith(NPY_MAGIC) else "it is not a zip file")
        raise ValueError(f"{path}: not a calippso/numpy .npz archive ({why})")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}
    except (OSError, EOFError, zipfile.BadZipFile) as error:
        raise ValueError(f"{path}: unreadable .npz file (damaged zip: {_one_line(error)})") \
            from None
    except ValueError as error:  # numpy refuses object arrays without allow_pickle
        if "pickle" in str(error):
            raise ValueError(f"{path}: not a calippso .npz file (it holds pickled Python "
                             "objects, which calippso never loads)") from None
        raise ValueError(f"{path}: unreadable .npz file ({_one_line(error)})") from None


def _one_line(error: Exception) -> str:
    return " ".join(str(error).split())


def read(path: Path) -> Packing:
    """Read the packing stored in an `.npz` (a packing file or a result file)."""
    data = load_arrays(path)
    missing = [k for k in ("positions", "diameters", "box") if k not in data]
    if missing:
        raise ValueError(f"{path}: not a calippso .npz file, missing keys {missing}")
    try:
        return packing_of(data)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def write(obj, path: Path) -> Path:
    """Write a `Packing` or `JammingResult` (anything with `to_arrays`) atomically."""
    if hasattr(obj, "save"):
        return obj.save(path)
    save_npz_atomic(Path(path), packing_arrays(obj))
    return Path(path)
