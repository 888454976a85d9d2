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

from ..geometry.boundaries import axis_name
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
    """One row per packing and wall: its name ("x = 0", "x = L", "cylinder"), its contacts,
    the load on it and its pressure.

    For a flat wall the load is the component along its axis of the particles' total force
    on it (`JammingResult.wall_loads`: ≤ 0 at 0, ≥ 0 at L, units of the forces); for a
    cylinder, the total outward force (`JammingResult.cylinder_load`). Pressures are force
    per length^(d−1) (`wall_pressures`, `cylinder_pressure`).
    """
    rows = []
    for k, result in enumerate(as_results(results)):
        boundaries = result.packing.boundaries
        walls = result.wall_contacts[:, 1]
        for axis in boundaries.wall_axes:
            for side, label in enumerate(("0", "L")):
                rows.append({"packing": k, "wall": f"{axis_name(axis)} = {label}",
                             "contacts": int(np.count_nonzero(walls == 2 * axis + side)),
                             "load": float(result.wall_loads[axis, side]),
                             "pressure": float(result.wall_pressures[axis, side])})
        if boundaries.cylinder_axes:
            flat = np.count_nonzero(walls < 2 * result.d)
            rows.append({"packing": k, "wall": "cylinder",
                         "contacts": int(walls.size - flat),
                         "load": float(result.cylinder_load),
                         "pressure": float(result.cylinder_pressure)})
    return rows
