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

import numpy as np

from calippso.atomic import digest
from calippso.checkpoint import Checkpoint as _Checkpoint

__all__ = ["Checkpoint", "Resumable", "digest"]


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


class Resumable:
    """A run whose whole state is the attributes named in `STATE`, saved by `state` into a
    checkpoint and set back by `restore`.

    Attributes
    ----------
    STATE : dict
        Attribute name → its type: float, int, or the dtype of an array (float64 and int64
        round-trip through the file bit for bit). The positions `x`, shape (N, d), must be
        one of them.
    """

    STATE: dict[str, type] = {}

    def state(self) -> dict:
        """Copies of the `STATE` attributes, keyed ``state_<name>``, for a checkpoint."""
        return {f"state_{name}": np.copy(getattr(self, name)) for name in self.STATE}

    def restore(self, saved: dict) -> None:
        """Continue from a `state()` dict (as read back by `Checkpoint.load`), bit for bit.

        Raises
        ------
        ValueError
            If the saved positions do not have the shape of this run's `x`.
        """
        positions = saved["state_x"]
        if positions.shape != self.x.shape:
            raise ValueError(f"checkpoint holds {positions.shape} positions, this run has "
                             f"{self.x.shape}")
        for name, kind in self.STATE.items():
            value = saved[f"state_{name}"]
            setattr(self, name, kind(value) if kind in (float, int)
                    else np.array(value, dtype=kind))
