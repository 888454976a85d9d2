"""`PooledSample`: positive values pooled over packings, with their empirical cumulative."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PooledSample"]


@dataclass(frozen=True)
class PooledSample:
    """Values pooled over packings, sorted, with the normalisation of their cumulative.

    The cumulative at the k-th smallest value (k = 1, 2, …) is C(x_k) = k / normalization.
    For forces the normalisation is the number of forces (C is the cumulative distribution
    G(f)); for gaps it is half the number of stable particles (C is Z(h) − z, the mean number
    of non-contact neighbours closer than h, per stable particle).

    Attributes
    ----------
    values : ndarray, shape (K,)
        The values in ascending order (dimensionless).
    groups : ndarray, shape (K,), int64
        Index of the packing each value comes from.
    group_normalizations : ndarray, shape (n_groups,)
        Each packing's share of the normalisation (they add up to `normalization`).
    """

    values: np.ndarray
    groups: np.ndarray
    group_normalizations: np.ndarray

    def __post_init__(self) -> None:
        values = np.asarray(self.values, dtype=np.float64)
        groups = np.asarray(self.groups, dtype=np.int64)
        norms = np.asarray(self.group_normalizations, dtype=np.float64)
        if values.ndim != 1 or groups.shape != values.shape:
            raise ValueError("values and groups must be 1-d arrays of equal length")
        if groups.size and (groups.min() < 0 or groups.max() >= norms.size):
            raise ValueError("groups must index group_normalizations")
        order = np.argsort(values, kind="stable")
        object.__setattr__(self, "values", values[order])
        object.__setattr__(self, "groups", groups[order])
        object.__setattr__(self, "group_normalizations", norms)

    @classmethod
    def from_values(cls, values: np.ndarray, normalization: float | None = None) -> "PooledSample":
        """A single-group sample; the normalisation defaults to the number of values."""
        values = np.asarray(values, dtype=np.float64).ravel()
        norm = float(values.size if normalization is None else normalization)
        return cls(values, np.zeros(values.size, dtype=np.int64), np.array([norm]))

    @classmethod
    def concatenate(cls, parts: list[tuple[np.ndarray, float]]) -> "PooledSample":
        """Pool (values, normalisation) pairs, one per packing."""
        values = [np.asarray(v, dtype=np.float64).ravel() for v, _ in parts]
        groups = [np.full(v.size, k, dtype=np.int64) for k, v in enumerate(values)]
        return cls(np.concatenate(values) if values else np.zeros(0),
                   np.concatenate(groups) if groups else np.zeros(0, dtype=np.int64),
                   np.array([float(norm) for _, norm in parts]))

    def select(self, packings) -> "PooledSample":
        """The values of some packings only, pooled in the order given (renumbered 0, 1, …).

        Parameters
        ----------
        packings : array_like of int, shape (P,)
            Group indices to keep (distinct).
        """
        keep = np.asarray(packings, dtype=np.int64).ravel()
        if np.unique(keep).size != keep.size or np.any((keep < 0) | (keep >= self.n_groups)):
            raise ValueError(f"packings must be distinct indices below {self.n_groups}")
        new_index = np.full(self.n_groups, -1, dtype=np.int64)
        new_index[keep] = np.arange(keep.size)
        mine = new_index[self.groups] >= 0
        return PooledSample(self.values[mine], new_index[self.groups[mine]],
                            self.group_normalizations[keep])

    def minima(self) -> np.ndarray:
        """The smallest value of each packing, shape (n_groups,) (nan for a packing without
        values)."""
        smallest = np.full(self.n_groups, np.nan)
        first = np.unique(self.groups, return_index=True)
        smallest[first[0]] = self.values[first[1]]
        return smallest

    def __len__(self) -> int:
        return int(self.values.size)

    @property
    def n_groups(self) -> int:
        """Number of packings pooled."""
        return int(self.group_normalizations.size)

    @property
    def normalization(self) -> float:
        """Total normalisation of the cumulative."""
        return float(self.group_normalizations.sum())

    def cumulative(self) -> tuple[np.ndarray, np.ndarray]:
        """The empirical cumulative: sorted values x_k and C(x_k) = k / normalization."""
        return self.values, np.arange(1, self.values.size + 1) / self.normalization

    def density(self, bins_per_decade: int = 5) -> tuple[np.ndarray, np.ndarray]:
        """dC/dx on logarithmic bins (empty bins dropped).

        Returns
        -------
        centres, density : ndarray, shape (B,)
            Geometric bin centres and the histogram divided by bin width and normalisation.
        """
        positive = self.values[self.values > 0]
        if positive.size == 0:
            return np.zeros(0), np.zeros(0)
        low, high = np.log10(positive[0]), np.log10(positive[-1])
        n_bins = max(1, int(np.ceil((high - low) * bins_per_decade)))
        edges = np.logspace(low, high, n_bins + 1)
        counts, edges = np.histogram(positive, bins=edges)
        keep = counts > 0
        centres = np.sqrt(edges[:-1] * edges[1:])
        return centres[keep], (counts / np.diff(edges) / self.normalization)[keep]
