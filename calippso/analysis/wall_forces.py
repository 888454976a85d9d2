"""Forces on a container's walls, kept apart from the particle–particle forces.

`JammingResult.forces` holds the particle–particle forces only (the distributions and
exponents of `calippso.analysis.forces` use those); the wall contacts and their forces are
`JammingResult.wall_contacts` and `wall_forces`. Here the wall forces are normalised by the
mean particle–particle force of their packing, so that both scales compare, and the load and
pressure on every wall are tabulated.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from ..boundaries import axis_name
from ..result import JammingResult
from ._inputs import as_results
from .sample import PooledSample

__all__ = ["normalized_wall_forces", "pooled_wall_forces", "wall_force_summary",
           "wall_load_rows"]


def normalized_wall_forces(result: JammingResult) -> np.ndarray:
    """Wall forces divided by the mean particle–particle force of the packing, shape (K,).

    Raw wall forces are returned when the packing has no particle–particle force.
    """
    forces = np.asarray(result.wall_forces, dtype=np.float64)
    pair_mean = float(np.mean(result.forces)) if result.forces.size else 1.0
    return forces / pair_mean


def pooled_wall_forces(results: JammingResult | Iterable[JammingResult]) -> PooledSample:
    """Wall forces of every packing, in units of its mean particle–particle force, pooled
    (normalised by their number: the cumulative is their distribution function)."""
    parts = [normalized_wall_forces(r) for r in as_results(results)]
    return PooledSample.concatenate([(part, part.size) for part in parts])


def wall_force_summary(sample: PooledSample) -> dict:
    """Count, mean, median, smallest and largest of pooled wall forces (units of the mean
    particle–particle force); NaN statistics when there are none."""
    values = sample.values
    if values.size == 0:
        return {"count": 0, "mean": float("nan"), "median": float("nan"),
                "min": float("nan"), "max": float("nan")}
    return {"count": int(values.size), "mean": float(values.mean()),
            "median": float(np.median(values)), "min": float(values[0]),
            "max": float(values[-1])}


def wall_load_rows(results: JammingResult | Iterable[JammingResult]) -> list[dict]:
    """One row per packing and walled axis: its wall contacts, the loads on the walls at 0
    and at L (`JammingResult.wall_loads`, units of the forces) and their pressures
    (`JammingResult.wall_pressures`, force per length^(d−1))."""
    rows = []
    for k, result in enumerate(as_results(results)):
        walls = result.wall_contacts[:, 1]
        for axis in result.packing.boundaries.wall_axes:
            rows.append({
                "packing": k, "axis": axis_name(axis),
                "contacts": int(np.count_nonzero(walls // 2 == axis)),
                "load_0": float(result.wall_loads[axis, 0]),
                "load_L": float(result.wall_loads[axis, 1]),
                "pressure_0": float(result.wall_pressures[axis, 0]),
                "pressure_L": float(result.wall_pressures[axis, 1]),
            })
    return rows
