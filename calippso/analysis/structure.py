"""Contact numbers, rattlers and isostaticity of one packing or of a pooled ensemble."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ..result import JammingResult
from ._inputs import as_results

__all__ = ["ContactStatistics", "contact_statistics"]


@dataclass(frozen=True)
class ContactStatistics:
    """Contact-network figures, pooled over the packings given.

    Attributes
    ----------
    d : int
        Dimension.
    n_packings : int
        Number of packings pooled.
    n_particles, n_stable, n_contacts : int
        Totals over the packings (particles, non-rattlers, contacts).
    mean_z : float
        Mean contact number over stable particles, 2 N_c / N_s (isostatic: 2d up to O(1/N)).
    rattler_fraction : float
        Rattlers / particles.
    contact_numbers : ndarray, shape (N_s,), int64
        Contact number of every stable particle (all packings concatenated).
    isostaticity_gaps : ndarray, shape (n_packings,), int64
        N_c − d (N_s − 1) − 1 of each packing.
    phi : ndarray, shape (n_packings,)
        Packing fraction of each packing.
    n_touching : int
        Pairs that touch outside the contact networks, over the packings: stable pairs and
        particle–wall pairs with zero force (`JammingResult.touching`). Not in
        `n_contacts`, `mean_z` or the contact numbers; counted as contacts they would raise
        each packing's isostaticity gap by their number.
    """

    d: int
    n_packings: int
    n_particles: int
    n_stable: int
    n_contacts: int
    mean_z: float
    rattler_fraction: float
    contact_numbers: np.ndarray
    isostaticity_gaps: np.ndarray
    phi: np.ndarray
    n_touching: int = 0

    @property
    def n_isostatic(self) -> int:
        """Packings with isostaticity gap 0."""
        return int(np.count_nonzero(self.isostaticity_gaps == 0))

    def histogram(self) -> tuple[np.ndarray, np.ndarray]:
        """Contact numbers z and the fraction of stable particles with each, shapes (K,), (K,)."""
        counts = np.bincount(self.contact_numbers)
        z = np.flatnonzero(counts)
        return z, counts[z] / counts.sum()


def contact_statistics(results: JammingResult | Iterable[JammingResult]) -> ContactStatistics:
    """Contact numbers, mean z, rattler fraction and isostaticity, pooled over `results`.

    Parameters
    ----------
    results : JammingResult or iterable of JammingResult
        Packings of one dimension.

    Returns
    -------
    ContactStatistics
    """
    items = as_results(results)
    z = [r.contact_numbers[~r.rattlers] for r in items]
    n_stable = sum(r.n_stable for r in items)
    n_contacts = sum(r.n_contacts for r in items)
    n_particles = sum(r.packing.n for r in items)
    return ContactStatistics(
        d=items[0].d,
        n_packings=len(items),
        n_particles=n_particles,
        n_stable=n_stable,
        n_contacts=n_contacts,
        mean_z=2.0 * n_contacts / n_stable if n_stable else float("nan"),
        rattler_fraction=sum(int(np.count_nonzero(r.rattlers)) for r in items) / n_particles,
        contact_numbers=np.concatenate(z).astype(np.int64),
        isostaticity_gaps=np.array([r.isostaticity_gap for r in items], dtype=np.int64),
        phi=np.array([r.phi for r in items], dtype=np.float64),
        n_touching=sum(len(r.touching) for r in items),
    )
