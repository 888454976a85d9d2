"""The ``precompress_pressure`` option of `jam`, kept until that option is removed.

`calippso.protocols.precompress` is the stage itself; call it before `jam` (the CLI's
``jam --precompress`` and the ensembles do). This module only adapts it to the option.
"""

from __future__ import annotations

import os

from .packing import Packing
from .protocols import precompress_checkpoint, precompress_note
from .protocols import precompress as _compress

__all__ = ["precompress", "precompress_checkpoint"]


def precompress(packing: Packing, pressure: float,
                checkpoint: str | os.PathLike | None = None) -> tuple[Packing, str]:
    """`calippso.protocols.precompress`, returning the compressed packing and its note."""
    run = _compress(packing, pressure, checkpoint=checkpoint)
    return run.packing, precompress_note(packing, run)
