"""Numba generators of compressed starting configurations (LS, FB, MLS, soft-sphere quench,
spherocylinders).

One calling convention for the sphere generators::

    f(diameters, d, *, seed=0, ...) -> GenerationResult

A generator that can continue from a configuration (LS, MLS) takes it as ``start=packing``
instead of diameters and d. LS, FB and the soft quench also make packings between flat hard
walls (``boundaries=calippso.Boundaries.walls(d, axes)``) or in a cylinder
(``calippso.Boundaries.cylinder(d, axes)``), or continue such a ``start=`` (LS); MLS refuses
both in one line. `poisson(diameters, d, *, phi, seed)` places
random centres and returns the `calippso.Packing` itself; `relax(packing)` runs the soft
quench from a given configuration, in its own box. The generators build only on
calippso's geometry base (`calippso.geometry.packing`, `calippso.geometry.periodic`, `calippso.geometry.neighbors`,
`calippso.atomic`, `calippso.checkpoint`, `calippso.geometry.boundaries`, and `calippso.geometry.rattlers` for
the rattler rule); importing this package never imports an LP solver.
"""

from . import diameters
from .initial import poisson
from .fb import force_biased
from .ls import lubachevsky_stillinger
from .mls import closest_jamming
from .result import GenerationResult
from .soft_quench import default_target_pressure, soft_quench
from .relax import relax

__all__ = ["GenerationResult", "diameters", "poisson", "force_biased", "lubachevsky_stillinger",
           "closest_jamming", "soft_quench", "default_target_pressure", "relax"]
