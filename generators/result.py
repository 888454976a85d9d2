"""`GenerationResult`: what every generator returns."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["GenerationResult", "HISTORY_FIELDS"]

#: Fields of `GenerationResult.history` (a numpy structured array, one record per sample).
HISTORY_FIELDS = [("time", np.float64), ("phi", np.float64), ("pressure", np.float64),
                  ("rate", np.float64)]


def make_history(rows: list[tuple[float, float, float, float]]) -> np.ndarray:
    """Structured history array from (time, phi, pressure, rate) tuples."""
    return np.array([tuple(row) for row in rows], dtype=HISTORY_FIELDS)


@dataclass(eq=False)
class GenerationResult:
    """A generated configuration and how the run went.

    Attributes
    ----------
    packing : calippso.Packing or SpherocylinderPacking
        The final configuration.
    reduced_pressure : float
        Reduced pressure p = βP/ρ at the end (nan where the algorithm has none, e.g. FB).
    steps : int
        Steps the run took: collisions processed (event-driven LS and MLS), force-biased
        steps (FB, spherocylinder FB) or FIRE steps (soft quench). The deprecated name
        `collisions` reads the same number.
    wall_time : float
        Seconds spent in the run (compile time of a first call included).
    history : ndarray, structured
        Samples of (time, phi, pressure, rate) along the run: simulation time (or step),
        packing fraction, reduced pressure, growth / contraction rate.
    status : str
        One sentence on why the run stopped.
    extra : dict
        Algorithm-specific details (documented by each generator).
    contacts : ndarray of int64, shape (M, 2), or None
        The contact network the generator found, when it knows one (`soft_quench`: the
        overlap network before the final shrink, rattlers removed recursively): pairs
        (i, j) with i < j, sorted lexicographically, in the packing's particle order. A hint
        for `calippso.jam(packing, network=result.contacts)`; None for the other generators.
        Particle pairs only: between walls, the wall contacts are not among them
        (`soft_quench` puts them in ``extra["wall_contacts"]``).
    """

    packing: Any
    reduced_pressure: float
    steps: int
    wall_time: float
    history: np.ndarray = field(default_factory=lambda: make_history([]))
    status: str = ""
    extra: dict = field(default_factory=dict)
    contacts: np.ndarray | None = None

    @property
    def collisions(self) -> int:
        """Deprecated name of `steps` (it counts FB and FIRE steps too, not only collisions)."""
        warnings.warn("GenerationResult.collisions is deprecated: use steps", DeprecationWarning,
                      stacklevel=2)
        return self.steps

    def __repr__(self) -> str:
        return (f"GenerationResult(phi={self.packing.phi:.6f}, "
                f"reduced_pressure={self.reduced_pressure:.3g}, steps={self.steps}, "
                f"wall_time={self.wall_time:.2f} s, status={self.status!r})")
