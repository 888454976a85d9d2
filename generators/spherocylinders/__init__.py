"""Random dense packings of spherocylinders: the force-biased algorithm of Bargiel (2008).

- `SpherocylinderPacking` — the configuration type (centres, unit axes, diameters, cylinder
  lengths, periodic box), with `phi` and `nematic_order()`.
- `shaft_distance`, `min_distance_ratio`, `overlapping_pairs` — exact geometry (Vega–Lago).
- `force_biased` — the generator; returns a `generators.result.GenerationResult`;
  `rigid_body_eps_rot` — its default rotation step per aspect ratio;
  `default_initial_density` and `start_density` — its default nominal density of the start
  (min(1.2, 12/γ), lowered when N is too small for the box rule).
- `write_xyz` — extended XYZ with orientations (OVITO); `render` — a PNG picture.
"""

from .fb import default_initial_density, force_biased, rigid_body_eps_rot, start_density
from .geometry import min_distance_ratio, overlapping_pairs, shaft_distance
from .packing import SpherocylinderPacking, min_particles_for_box, spherocylinder_volume
from .render import render
from .xyz import read_xyz, write_xyz

__all__ = ["SpherocylinderPacking", "default_initial_density", "force_biased", "min_distance_ratio",
           "min_particles_for_box", "overlapping_pairs", "read_xyz", "render",
           "rigid_body_eps_rot", "shaft_distance", "spherocylinder_volume", "start_density",
           "write_xyz"]
