"""Numba generators of compressed starting configurations (LS, FB, MLS, soft-sphere quench,
spherocylinders).

Importing this package never imports an LP solver; the generators return `calippso.Packing`.
"""

from . import diameters
from .initial import poisson
from .fb import force_biased
from .ls import lubachevsky_stillinger
from .mls import closest_jamming
from .result import GenerationResult
from .soft_quench import soft_quench

__all__ = ["GenerationResult", "diameters", "poisson", "force_biased", "lubachevsky_stillinger",
           "closest_jamming", "soft_quench"]
