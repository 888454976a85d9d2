"""Crystal packings for tests: square, triangular, kagome, honeycomb, simple cubic, FCC, BCC and
the checkerboard lattices D_d in periodic boxes.

Every builder returns the lattice with touching nearest neighbours (diameter 1 times
`fill`, a number ≤ 1: `fill` < 1 leaves every contact open by the same relative gap, so that
the LP has to grow the spheres back to contact).
"""

from __future__ import annotations

import itertools

import numpy as np

from calippso import Packing

__all__ = ["square", "triangular", "fcc", "bcc", "kagome", "honeycomb", "simple_cubic",
           "checkerboard", "CONTACTS_PER_PARTICLE"]

#: Nearest neighbours of a site (the contacts of the touching lattice).
CONTACTS_PER_PARTICLE = {"square": 4, "triangular": 6, "fcc": 12, "bcc": 8, "kagome": 4,
                         "honeycomb": 3, "simple_cubic": 6, "d4": 24, "d5": 40}


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


def kagome(m: int, fill: float = 1.0) -> Packing:
    """Kagome lattice of spacing 1 in a rectangular box 2m × 2m√3 (N = 6m², m ≥ 2).

    Corner-sharing triangles: the sites (0, 0), (1, 0), (1/2, √3/2) of a triangular Bravais
    lattice of spacing 2, two Bravais points per rectangular cell (2 × 2√3). Four contacts
    per disc.
    """
    cell = np.array([2.0, 2.0 * np.sqrt(3.0)])
    triangle = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.5 * np.sqrt(3.0)]])
    bravais = np.array([[0.0, 0.0], [1.0, np.sqrt(3.0)]])
    base = _grid((m, m), 2) * cell
    sites = (base[:, None, None, :] + bravais[None, :, None, :]
             + triangle[None, None, :, :]).reshape(-1, 2)
    return _packing(sites, cell * m, fill)


def honeycomb(m: int, fill: float = 1.0) -> Packing:
    """Honeycomb lattice of spacing 1 in a rectangular box m√3 × 3m (N = 4m², m ≥ 2).

    Four sites per rectangular cell (√3 × 3): (0, 0), (0, 1), (√3/2, 3/2), (√3/2, 5/2).
    Three contacts per disc.
    """
    half = 0.5 * np.sqrt(3.0)
    cell = np.array([np.sqrt(3.0), 3.0])
    basis = np.array([[0.0, 0.0], [0.0, 1.0], [half, 1.5], [half, 2.5]])
    sites = (_grid((m, m), 2)[:, None, :] * cell + basis[None, :, :]).reshape(-1, 2)
    return _packing(sites, cell * m, fill)


def simple_cubic(m: int, fill: float = 1.0) -> Packing:
    """m × m × m simple cubic lattice of spacing 1 (N = m³, box m). Six contacts per
    sphere."""
    return _packing(_grid((m, m, m), 3), np.full(3, float(m)), fill)


def checkerboard(d: int, m: int, fill: float = 1.0) -> Packing:
    """The checkerboard lattice D_d (integer points with an even sum of coordinates) scaled to
    nearest-neighbour distance 1, in a cube of m periods (side m√2, N = (2m)^d / 2, m ≥ 2).

    D_4 and D_5 are the densest lattice packings in four and five dimensions, with 24 and 40
    contacts per sphere.
    """
    points = _grid((2 * m,) * d, d)
    sites = points[points.sum(axis=1) % 2 == 0] / np.sqrt(2.0)
    return _packing(sites, np.full(d, m * np.sqrt(2.0)), fill)
