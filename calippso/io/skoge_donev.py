"""Skoge–Donev LS text output and the stripped variant used by CALiPPSO.jl's examples.

Full format: line 1 d; line 2 "N n_species"; line 3 the count of each species; line 4 the
diameter of each species; line 5 the d×d box matrix (row-major, diagonal here); line 6 the
periodicity flags ("T T T"); then N lines of d coordinates.

Stripped format: line 1 d; line 2 N; line 3 the diameter; then N lines of d coordinates in
[0, 1) (box side 1 implied).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geometry.packing import Packing
from .sheared import refuse_sheared


def _numbers(line: str, path: Path, number: int, kind=float) -> list:
    try:
        return [kind(token) for token in line.split()]
    except ValueError:
        raise ValueError(f"{path}, line {number}: expected numbers, got {line.strip()[:60]!r}") from None


def read(path: Path) -> Packing:
    """Read either Skoge–Donev variant (told apart by the number of fields on line 2)."""
    try:
        lines = Path(path).read_text().splitlines()
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file (expected Skoge-Donev LS output)") from None
    lines = [line for line in lines if line.strip()]
    if len(lines) < 4:
        raise ValueError(f"{path}: too short for Skoge-Donev LS output ({len(lines)} lines)")
    first_line = lines[0].split()
    d = int(first_line[0]) if len(first_line) == 1 and first_line[0].isdigit() else None
    if d is None or d < 2:
        raise ValueError(f"{path}, line 1: expected the dimension (an integer ≥ 2), got {lines[0]!r}")
    header = _numbers(lines[1], path, 2, int)
    if len(header) == 1:
        n = header[0]
        (diameter,) = _numbers(lines[2], path, 3)
        diameters = np.full(n, diameter)
        box = np.ones(d)
        first = 3
        flags = ["T"] * d
    elif len(header) == 2:
        n, species = header
        counts = _numbers(lines[2], path, 3, int)
        sizes = _numbers(lines[3], path, 4)
        if len(counts) != species or len(sizes) != species or sum(counts) != n:
            raise ValueError(f"{path}, lines 3-4: species counts {counts} and diameters {sizes} "
                             f"do not match N = {n} with {species} species")
        diameters = np.repeat(sizes, counts)
        matrix = np.array(_numbers(lines[4], path, 5))
        if matrix.size != d * d:
            raise ValueError(f"{path}, line 5: expected a {d}x{d} box matrix, got {matrix.size} numbers")
        matrix = matrix.reshape(d, d)
        if np.any(matrix[~np.eye(d, dtype=bool)] != 0):
            raise ValueError(f"{path}, line 5: only rectangular (diagonal) boxes are supported")
        box = np.diag(matrix).copy()
        flags = lines[5].upper().split()
        first = 6
    else:
        raise ValueError(f"{path}, line 2: expected 'N' or 'N n_species', got {lines[1]!r}")
    if "F" in flags:
        raise ValueError(f"{path}, line 6: periodicity flags {' '.join(flags)!r}: calippso "
                         f"reads periodic Skoge-Donev files only (T for every axis)")
    body = lines[first:first + n]
    if len(body) < n:
        raise ValueError(f"{path}: truncated, {len(body)} coordinate lines where N = {n}")
    positions = np.empty((n, d))
    for k, line in enumerate(body):
        values = line.split()[:d]
        if len(values) < d:
            raise ValueError(f"{path}: every coordinate line needs {d} numbers; the line of "
                             f"particle {k} has {len(values)}: {line.strip()[:60]!r}")
        try:
            positions[k] = [float(v) for v in values]
        except ValueError:
            raise ValueError(f"{path}: non-numeric coordinates for particle {k}: "
                             f"{line.strip()[:60]!r}") from None
    try:
        return Packing(positions, diameters, box)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None


def write(packing: Packing, path: Path) -> Path:
    """Write the full Skoge–Donev format (species = distinct diameters, in order of appearance).

    Particles are grouped by species, as the format requires; 17 significant digits keep
    float64 positions exact. A box with walls is refused (the format's flags are written
    "T" for every axis).
    """
    refuse_sheared(packing, "Skoge-Donev files")
    if not packing.boundaries.is_periodic:
        small = packing.d <= 3   # extended XYZ and GSD; XYZ holds flat walls only
        formats = [".npz", ".h5", *([".xyz"] if small and not packing.boundaries.cylinder_axes
                                    else []), *([".gsd"] if small else [])]
        raise ValueError(f"Skoge-Donev files hold periodic packings here, this one has "
                         f"{packing.boundaries.describe()}: write {', '.join(formats[:-1])} "
                         f"or {formats[-1]} instead")
    sizes, inverse = np.unique(packing.diameters, return_inverse=True)
    order = np.argsort(inverse, kind="stable")
    counts = np.bincount(inverse, minlength=sizes.size)
    d = packing.d
    lines = [str(d), f"{packing.n} {sizes.size}", " ".join(map(str, counts)),
             " ".join(f"{s:.17g}" for s in sizes),
             " ".join(f"{v:.17g}" for v in np.diag(packing.box).ravel()),
             " ".join(["T"] * d)]
    lines += [" ".join(f"{v:.17g}" for v in row) for row in packing.wrapped().positions[order]]
    Path(path).write_text("\n".join(lines) + "\n")
    return Path(path)
