"""Checkpoints of long event-driven runs (LS and MLS): atomic saves and exact resumption.

A run with ``checkpoint=path`` writes its whole state to `path` (an ``.npz``) at the end of a
pressure window, at most every `every` seconds of wall time, and once more when it finishes.
The state between two windows is complete (positions, velocities, diameter scale, Verlet skin,
counters, history and the protocol's own variables), because every window of
`generators.edmd.run_window` starts from it alone: a run resumed from a checkpoint therefore
continues bit-for-bit as the uninterrupted run would have.

Writes are atomic: the state goes to a temporary file in the same folder, is flushed to disk,
and is then renamed over `path`, so a run killed at any moment (even by SIGKILL) leaves either
the previous checkpoint or the new one, never a torn file.

A checkpoint remembers what it belongs to: the generator, its parameters and a digest of the
start configuration. A call whose inputs differ refuses the file with a ValueError that names
the difference, instead of silently continuing someone else's run.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from calippso.atomic import save_npz_atomic
from calippso.checkpoint import digest

__all__ = ["Checkpoint", "digest"]

#: Version of the file layout; a file with another version is refused.
FORMAT_VERSION = 1


class Checkpoint:
    """Save and restore the state of one generator run.

    Parameters
    ----------
    path : str or PathLike or None
        The checkpoint file (``.npz`` is appended when missing). None disables checkpointing:
        `load` returns None and `maybe_save` / `save` do nothing.
    kind : str
        Generator name ("lubachevsky_stillinger", "closest_jamming").
    signature : dict
        JSON-serialisable description of the call (parameters and start digest). A stored
        checkpoint whose signature differs is refused.
    every : float
        Smallest wall time, in seconds, between two saves by `maybe_save` (0: every window).

    Raises
    ------
    ValueError
        If `every` is negative or not finite.
    """

    def __init__(self, path, kind: str, signature: dict, every: float = 60.0) -> None:
        if not (np.isfinite(every) and every >= 0):
            raise ValueError(f"checkpoint_every must be a finite number of seconds >= 0, "
                             f"got {every!r}")
        self.path = None if path is None else Path(path)
        if self.path is not None and self.path.suffix != ".npz":
            self.path = self.path.with_name(self.path.name + ".npz")
        self.kind = kind
        self.signature = json.dumps({"kind": kind, **signature}, sort_keys=True)
        self.every = float(every)
        self._last = time.monotonic()

    @property
    def enabled(self) -> bool:
        """Whether a path was given."""
        return self.path is not None

    def load(self) -> dict | None:
        """The stored state, or None when there is no checkpoint file yet.

        Returns
        -------
        dict or None
            The arrays and scalars given to `save` (scalars as 0-d arrays; strings as str).

        Raises
        ------
        ValueError
            If the file is not a checkpoint, has another format version, or belongs to a call
            with other inputs (the message names the differing fields).
        """
        if self.path is None or not self.path.exists():
            return None
        try:
            with np.load(self.path, allow_pickle=False) as data:
                state = {key: data[key] for key in data.files}
        except (OSError, ValueError, EOFError) as error:
            raise ValueError(f"{self.path}: not a readable generator checkpoint ({error})") from None
        if "_signature" not in state or "_version" not in state:
            raise ValueError(f"{self.path}: not a generator checkpoint (no signature)")
        if int(state["_version"]) != FORMAT_VERSION:
            raise ValueError(f"{self.path}: checkpoint format {int(state['_version'])}, "
                             f"this version reads format {FORMAT_VERSION}")
        stored = str(state["_signature"])
        if stored != self.signature:
            raise ValueError(f"{self.path}: checkpoint of another run; it differs in "
                             f"{_differences(stored, self.signature)}. Use another path, or "
                             f"delete the file to start afresh")
        return {key: (str(value) if value.dtype.kind == "U" else value)
                for key, value in state.items() if not key.startswith("_")}

    def maybe_save(self, state: dict) -> bool:
        """Save `state` if at least `every` seconds passed since the last save; return whether."""
        if self.path is None or time.monotonic() - self._last < self.every:
            return False
        self.save(state)
        return True

    def save(self, state: dict) -> None:
        """Write `state` (arrays and scalars) atomically to the checkpoint path."""
        if self.path is None:
            return
        arrays = {key: np.asarray(value) for key, value in state.items()}
        arrays["_signature"] = np.asarray(self.signature)
        arrays["_version"] = np.asarray(FORMAT_VERSION)
        save_npz_atomic(self.path, arrays)
        self._last = time.monotonic()


def _differences(stored: str, wanted: str) -> str:
    """Names of the signature fields that differ, for the error message."""
    a, b = json.loads(stored), json.loads(wanted)
    keys = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    return ", ".join(f"{k} (checkpoint {a.get(k)!r}, this call {b.get(k)!r})" for k in keys)
