"""Readers and writers: one module per file format, one `read` / `write` dispatch.

Formats
-------
- ``.npz``: our own (a `Packing`, or a full `JammingResult`), any d.
- Skoge–Donev LS text output and the stripped CALiPPSO.jl variant (``.dat``, ``.txt``), any d.
- PackingGeneration: a folder with ``packing.xyzd`` + ``packing.nfo`` + ``generation.conf``,
  or the ``.xyzd`` path itself (d = 3).
"""

from __future__ import annotations

import os
from pathlib import Path

from ..packing import Packing
from . import npz, packing_generation, skoge_donev

__all__ = ["read", "write"]


def _format_of(path: Path) -> str:
    if path.is_dir():
        if (path / "packing.xyzd").exists():
            return "packing_generation"
        raise ValueError(f"{path} is a folder without packing.xyzd: not a PackingGeneration folder")
    suffix = path.suffix.lower()
    if suffix == ".xyzd":
        return "packing_generation"
    if suffix == ".npz":
        return "npz"
    if suffix in (".dat", ".txt", ""):
        return "skoge_donev"
    raise ValueError(
        f"unknown file format {suffix!r} for {path}: expected .npz, .xyzd (or a PackingGeneration "
        f"folder), or Skoge-Donev text (.dat/.txt)"
    )


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
    kind = _format_of(path)
    if kind == "packing_generation":
        return packing_generation.read(path)
    if kind == "npz":
        return npz.read(path)
    return skoge_donev.read(path)


def write(obj, path: str | os.PathLike) -> Path:
    """Write a `Packing` (or a `JammingResult`) in the format named by the extension.

    ``.npz`` stores a result in full; the text formats store the packing only.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        return npz.write(obj, path)
    packing = getattr(obj, "packing", obj)
    if suffix in (".dat", ".txt"):
        return skoge_donev.write(packing, path)
    if suffix == ".xyzd":
        return packing_generation.write(packing, path)
    raise ValueError(f"unknown output format {suffix!r}: expected .npz, .dat, .txt or .xyzd")
