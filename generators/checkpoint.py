"""Checkpoints of long generator runs (LS, MLS, force-biased spherocylinders, soft quench).

The design is `calippso.checkpoint.Checkpoint`, shared with `calippso.jam`: the whole state
at the end of a window (at a pause of a minimisation, for the quench), saved atomically at
most every `every` seconds and once more at the end, and refused when it belongs to a call
with other inputs. Every window of `generators.edmd.run_window`, and every stretch of FIRE
steps of `generators.soft_quench`, starts from that state alone, so a resumed run continues
bit for bit as the uninterrupted run would have.
"""

from __future__ import annotations

import os

from calippso.atomic import digest
from calippso.checkpoint import Checkpoint as _Checkpoint

__all__ = ["Checkpoint", "digest"]


class Checkpoint(_Checkpoint):
    """`calippso.checkpoint.Checkpoint` of a generator run ("a generator checkpoint" in its
    messages).

    Parameters
    ----------
    path : str or PathLike or None
        The checkpoint file (``.npz`` is appended when missing); None disables it.
    kind : str
        Generator name ("lubachevsky_stillinger", "closest_jamming", ...).
    signature : dict
        JSON-serialisable parameters and start digest of the call.
    every : float
        Smallest wall time, in seconds, between two saves by `maybe_save`.
    """

    def __init__(self, path: str | os.PathLike | None, kind: str, signature: dict,
                 every: float = 60.0) -> None:
        super().__init__(path, kind, signature, every, label="generator")
