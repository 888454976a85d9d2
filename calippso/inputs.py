"""Checks of a configuration given to `calippso.jam` (and to `calippso.protocols.precompress`).

`Packing` itself validates shapes, values and sizes (`calippso.geometry.packing`); a network hint is
checked by `calippso.certification.network_guess.check_network_hint`. What is left is checked here: how the
configuration is passed, whether it has enough particles to jam, and whether its particles
are apart. Every check raises with a message that names the bad argument and what was
expected.
"""

from __future__ import annotations

import numpy as np

from .geometry.neighbors import SAME_PLACE, NeighborSearch, check_no_duplicates
from .geometry.packing import Packing

__all__ = ["as_packing", "check_enough_particles", "check_input_overlaps"]


def as_packing(packing: Packing | np.ndarray, diameters=None, box=None) -> Packing:
    """`jam`'s first arguments as one `Packing`.

    Parameters
    ----------
    packing : Packing or array_like, shape (N, d)
        The configuration, or its positions (then `diameters` and `box` are required).
    diameters : array_like, shape (N,), optional
        Diameters, with positions only.
    box : array_like, shape (d,) or float, optional
        Box side lengths, with positions only.

    Raises
    ------
    TypeError
        A `Packing` together with `diameters` or `box`, or positions without both.
    """
    if isinstance(packing, Packing):
        if diameters is not None or box is not None:
            raise TypeError("pass either a Packing, or positions with diameters and box")
        if packing.box_matrix is not None:
            raise ValueError("this packing's box is sheared (box_matrix): jam it with "
                             "box='deformable'; the fixed-box loop needs a rectangular box")
        return packing
    if diameters is None or box is None:
        raise TypeError("jam(positions, diameters, box): diameters and box are required")
    return Packing(packing, diameters, box)


def check_enough_particles(n: int, d: int) -> None:
    """Raise ValueError when N particles cannot jam in d dimensions.

    Under the minimum-image convention a stable particle touches d + 1 distinct others, and an
    isostatic network of N_s particles has N_c = d (N_s − 1) + 1 ≤ N_s (N_s − 1) / 2 contacts:
    so N_s ≥ 2 d + 1, whatever the box.
    """
    least = 2 * d + 1
    if n < least:
        raise ValueError(f"cannot jam {n} particle(s) in d = {d}: a jammed packing in a "
                         f"periodic box needs at least 2 d + 1 = {least} particles (each stable "
                         f"particle touches d + 1 others, and an isostatic network of N_s "
                         f"particles has d (N_s - 1) + 1 contacts)")


def check_input_overlaps(search: NeighborSearch, tolerance: float) -> None:
    """Raise ValueError naming duplicated or overlapping particles of an input.

    Overlaps down to a relative gap h = |r|/σ − 1 > −`tolerance` are round-off and accepted.

    Parameters
    ----------
    search : NeighborSearch
        The input in the loop's units (mean diameter 1): centres closer than `SAME_PLACE`
        are duplicates.
    tolerance : float
        Largest accepted overlap, as a relative gap (dimensionless, ≥ 0).
    """
    check_no_duplicates(search.positions, search.box, SAME_PLACE, search.periodic)
    close = search.pairs_within(float(search.diameters.max()))
    gaps = close.gaps
    if gaps.size and gaps.min() < -tolerance:
        k = int(np.argmin(gaps))
        count = int(np.count_nonzero(gaps < -tolerance))
        raise ValueError(
            f"overlapping particles in the input: {count} pair(s) overlap beyond round-off "
            f"(h < -{tolerance:g}), the worst is ({close.i[k]}, {close.j[k]}) with gap "
            f"h = |r|/sigma - 1 = {gaps[k]:.3e}; shrink every diameter by the factor 1 + h "
            f"of the worst pair, or make the start with a generator")
