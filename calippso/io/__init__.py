"""Readers and writers: one module per file format, one `read` / `write` dispatch.

Formats (chosen by extension; a folder is a PackingGeneration folder)
--------------------------------------------------------------------
==========================  ======================  =====  ===================================
format                      extensions              d      holds
==========================  ======================  =====  ===================================
calippso npz                ``.npz``                any    packing, or a full result
HDF5 (needs h5py)           ``.h5``, ``.hdf5``      any    packing, or a full result
extended XYZ (ASE, OVITO)   ``.xyz``, ``.extxyz``   2, 3   packing (+ rattlers, contacts)
GSD (HOOMD, OVITO; gsd)     ``.gsd``                2, 3   packing (+ rattlers, contacts)
Skoge–Donev / CALiPPSO.jl   ``.dat``, ``.txt``      any    packing
PackingGeneration           ``.xyzd`` or a folder   3      packing (xyzd + nfo + conf)
==========================  ======================  =====  ===================================

Writing a packing to a format that cannot hold it (d = 4 to extended XYZ, for instance)
raises `ValueError` naming the formats that can.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..geometry.packing import Packing
from . import extxyz, gsd, hdf5, npz, packing_generation, skoge_donev

__all__ = ["read", "read_result", "write", "SUFFIXES"]

#: Extension → format module name.
SUFFIXES: dict[str, str] = {
    ".npz": "npz",
    ".h5": "hdf5",
    ".hdf5": "hdf5",
    ".xyz": "extxyz",
    ".extxyz": "extxyz",
    ".gsd": "gsd",
    ".dat": "skoge_donev",
    ".txt": "skoge_donev",
    ".xyzd": "packing_generation",
}

_MODULES = {
    "npz": npz,
    "hdf5": hdf5,
    "extxyz": extxyz,
    "gsd": gsd,
    "skoge_donev": skoge_donev,
    "packing_generation": packing_generation,
}


def _format_of(path: Path) -> str:
    if path.is_dir():
        if (path / "packing.xyzd").exists():
            return "packing_generation"
        raise ValueError(f"{path} is a folder without packing.xyzd: not a PackingGeneration folder")
    suffix = path.suffix.lower()
    if suffix == "":
        return "skoge_donev"
    if suffix not in SUFFIXES:
        raise ValueError(
            f"unknown file format {suffix!r} for {path}: expected one of "
            f"{', '.join(SUFFIXES)} or a PackingGeneration folder"
        )
    return SUFFIXES[suffix]


def read(path: str | os.PathLike) -> Packing:
    """Read a packing from any supported format (chosen by extension and content).

    Parameters
    ----------
    path : str or PathLike
        A file, or a PackingGeneration folder.

    Returns
    -------
    Packing

    Raises
    ------
    FileNotFoundError
        If the path does not exist.
    ValueError
        If the format is unknown or the file is malformed (the message says where).
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no such file or folder: {path}")
    return _MODULES[_format_of(path)].read(path)


def read_result(path: str | os.PathLike):
    """Read a full `JammingResult` from an `.npz` or HDF5 result file.

    Raises
    ------
    FileNotFoundError
        If the file does not exist.
    ValueError
        If the file is not a result file (a bare packing, another format, or unreadable).
    """
    from ..result import JammingResult

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such file: {path}")
    kind = SUFFIXES.get(path.suffix.lower())
    if kind == "hdf5":
        return hdf5.read_result(path)
    if kind != "npz":
        raise ValueError(
            f"{path}: results are stored as .npz or .h5, not {path.suffix or 'no extension'}"
        )
    arrays = npz.load_arrays(path)
    try:
        return JammingResult.from_arrays(arrays)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def write(obj, path: str | os.PathLike) -> Path:
    """Write a `Packing` (or a `JammingResult`) in the format named by the extension.

    ``.npz`` and ``.h5`` store a result in full; the other formats store the packing (extended
    XYZ and GSD also mark rattlers and contact numbers).

    Raises
    ------
    ValueError
        If the extension is unknown, or the format cannot hold this packing (its d).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise ValueError(
            f"unknown output format {suffix!r} for {path}: expected one of {', '.join(SUFFIXES)}"
        )
    kind = SUFFIXES[suffix]
    if kind in ("npz", "hdf5", "extxyz", "gsd"):
        return _MODULES[kind].write(obj, path)
    return _MODULES[kind].write(getattr(obj, "packing", obj), path)
