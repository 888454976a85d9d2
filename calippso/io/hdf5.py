"""HDF5 via h5py (optional): a `Packing` or a full `JammingResult`, any d.

The file holds the same keys as our `.npz` format (see `calippso.result`): one dataset per
array at the root, string scalars (``status``, ``solver``, ``boundaries``) as root
attributes. The root
attribute ``calippso_format`` is "packing" or "result".
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..atomic import atomic_path
from ..geometry.packing import Packing, packing_arrays, packing_of

__all__ = ["read", "read_result", "write"]


def _h5py():
    try:
        import h5py
    except ImportError:
        raise ValueError(
            "HDF5 files need the h5py package: pip install 'calippso[formats]'"
        ) from None
    return h5py


def write(obj, path: Path) -> Path:
    """Write a `Packing` or a `JammingResult` (anything with `to_arrays`) to an HDF5 file."""
    h5py = _h5py()
    if hasattr(obj, "to_arrays"):
        arrays, kind = obj.to_arrays(), "result"
    else:
        arrays, kind = packing_arrays(obj), "packing"
    path = Path(path)
    with atomic_path(path) as temporary, h5py.File(temporary, "w") as file:
        file.attrs["calippso_format"] = kind
        for key, value in arrays.items():
            value = np.asarray(value)
            if value.dtype.kind == "U":
                file.attrs[key] = str(value)
            else:
                file.create_dataset(key, data=value)
    return path


def _arrays(path: Path) -> dict:
    h5py = _h5py()
    try:
        with h5py.File(path, "r") as file:
            arrays = {key: file[key][()] for key in file.keys()}
            arrays.update(
                {
                    key: np.array(str(value))
                    for key, value in file.attrs.items()
                    if key != "calippso_format"
                }
            )
    except OSError as error:
        raise ValueError(f"{path}: not a readable HDF5 file ({error})") from None
    missing = [k for k in ("positions", "diameters", "box") if k not in arrays]
    if missing:
        raise ValueError(f"{path}: not a calippso HDF5 file, missing datasets {missing}")
    return arrays


def read(path: Path) -> Packing:
    """Read the packing stored in an HDF5 file written by `write`."""
    try:
        return packing_of(_arrays(path))
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def read_result(path: Path):
    """Read a `JammingResult` stored in an HDF5 file written by `write`."""
    from ..result import JammingResult

    try:
        return JammingResult.from_arrays(_arrays(path))
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
