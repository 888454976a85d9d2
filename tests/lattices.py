"""Crystal packings for tests: square, triangular, FCC and BCC lattices in periodic boxes.

Every builder returns the lattice with touching nearest neighbours (diameter 1 times
`fill`, a number ≤ 1: `fill` < 1 leaves every contact open by the same relative gap, so that
the LP has to grow the spheres back to contact).
"""

from __future__ import annotations

import itertools

import numpy as np

from calippso import Packing

__all__ = ["square", "triangular", "fcc", "bcc", "CONTACTS_PER_PARTICLE"]

#: Nearest neighbours of a site (the contacts of the touching lattice).
CONTACTS_PER_PARTICLE = {"square": 4, "triangular": 6, "fcc": 12, "bcc": 8}


def _grid(cells, d: int) -> np.ndarray:
    return np.array(list(itertools.product(*(range(c) for c in cells))), dtype=np.float64).reshape(-1, d)


def _packing(sites: np.ndarray, box: np.ndarray, fill: float) -> Packing:
    if not 0 < fill <= 1:
        raise ValueError(f"fill must lie in (0, 1], got {fill}")
    return Packing(sites % box, np.full(sites.shape[0], float(fill)), box)


def square(m: int, fill: float = 1.0) -> Packing:
    """m × m square lattice of spacing 1 (N = m², box m × m). Four contacts per disc."""
    return _packing(_grid((m, m), 2), np.full(2, float(m)), fill)


def triangular(m: int, fill: float = 1.0) -> Packing:
    """Triangular lattice of spacing 1 in a rectangular box m × m√3 (N = 2m², m ≥ 3).

    Two sites per rectangular cell (1 × √3): (0, 0) and (1/2, √3/2). Six contacts per disc.
    """
    cell = np.array([1.0, np.sqrt(3.0)])
    base = _grid((m, m), 2) * cell
    sites = np.concatenate([base, base + 0.5 * cell])
    return _packing(sites, cell * m, fill)


def fcc(m: int, fill: float = 1.0) -> Packing:
    """FCC lattice of nearest-neighbour distance 1 in a cube of m cubic cells (N = 4m³)."""
    a = np.sqrt(2.0)
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    cells = _grid((m, m, m), 3)
    sites = (cells[:, None, :] + basis[None, :, :]).reshape(-1, 3) * a
    return _packing(sites, np.full(3, a * m), fill)


def bcc(m: int, fill: float = 1.0) -> Packing:
    """BCC lattice of nearest-neighbour distance 1 in a cube of m cubic cells (N = 2m³)."""
    a = 2.0 / np.sqrt(3.0)
    basis = np.array([[0, 0, 0], [0.5, 0.5, 0.5]])
    cells = _grid((m, m, m), 3)
    sites = (cells[:, None, :] + basis[None, :, :]).reshape(-1, 3) * a
    return _packing(sites, np.full(3, a * m), fill)
