"""calippso: jam hard-particle packings exactly, and read what the jammed packing says.

The top-level import is light (numpy only). The LP machinery (`jam`), the readers and the
analysis are imported on first use; numba is never imported from here (the Numba generators
live in the separate `generators` package).
"""

from __future__ import annotations

import importlib

from .geometry.boundaries import Boundaries
from .geometry.packing import Packing

__version__ = "0.1.0"

_LAZY = {
    "jam": ("calippso.ilp", "jam"),
    "JamSettings": ("calippso.settings", "JamSettings"),
    "JammingError": ("calippso.errors", "JammingError"),
    "JammingResult": ("calippso.result", "JammingResult"),
    "StopReason": ("calippso.history", "StopReason"),
    "load_result": ("calippso.result", "load_result"),
    "read": ("calippso.io", "read"),
    "write": ("calippso.io", "write"),
    "analysis": ("calippso.analysis", None),  # the module itself
    "report": ("calippso.reporting", "report"),
    "jamming_category": ("calippso.categories", "jamming_category"),
    "NetworkFirstSettle": ("calippso.routes", "NetworkFirstSettle"),
}

__all__ = ["Packing", "Boundaries", "__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        module_name, attribute = _LAZY[name]
        module = importlib.import_module(module_name)
        value = module if attribute is None else getattr(module, attribute)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'calippso' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
