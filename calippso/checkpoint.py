"""Checkpoints of long runs: atomic saves and exact resumption, one design for every run.

`calippso.jam` saves the loop's state after every LP; the event-driven generators (LS, MLS,
force-biased spherocylinders) save theirs at the end of a window, at most every `every`
seconds. A run given ``checkpoint=path`` writes its whole state to `path` (an ``.npz``), and a
new call with the same inputs resumes from it: the steps that follow are the ones the
uninterrupted run would have taken, so the result is the same bit for bit.

Writes are atomic (`calippso.atomic`): the state goes to a temporary file in the same folder,
is flushed to disk, and is then renamed over `path`, so a run killed at any moment (even by
SIGKILL) leaves either the previous checkpoint or the new one, never a torn file.

A checkpoint remembers what it belongs to: the kind of run, its parameters and digests of its
inputs (`calippso.atomic.digest`). A call whose inputs differ refuses the file with a
ValueError that names the difference, instead of silently continuing someone else's run.

This module imports numpy and `calippso.atomic` only, so that the Numba generators can use it
without the LP machinery.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from .atomic import save_npz_atomic

__all__ = ["Checkpoint", "FORMAT_VERSION"]

#: Version of the file layout; a file with another version is refused.
FORMAT_VERSION = 1
#: Keys the checkpoint adds to the saved state (a state's own keys must not start with "_").
_SIGNATURE, _VERSION = "_signature", "_version"
#: Keys of a `calippso.jam` checkpoint written before jam used this design.
_OLD_JAM_KEYS = ("signature", "format_version")


class Checkpoint:
    """Save and restore the state of one run.

    Parameters
    ----------
    path : str or PathLike or None
        The checkpoint file (``.npz`` is appended when missing). None disables checkpointing:
        `load` returns None and `maybe_save` / `save` do nothing.
    kind : str
        The kind of run ("jam", "lubachevsky_stillinger", "closest_jamming", ...).
    signature : dict
        JSON-serialisable description of the call (parameters and input digests). A stored
        checkpoint whose signature differs is refused.
    every : float
        Smallest wall time, in seconds, between two saves by `maybe_save` (0: every call).
    label : str, optional
        What the messages call such a file ("a jam checkpoint", "a generator checkpoint");
        `kind` by default.

    Raises
    ------
    ValueError
        If `every` is negative or not finite.
    """

    def __init__(self, path: str | os.PathLike | None, kind: str, signature: dict,
                 every: float = 60.0, label: str | None = None) -> None:
        if not (np.isfinite(every) and every >= 0):
            raise ValueError(f"checkpoint_every must be a finite number of seconds >= 0, "
                             f"got {every!r}")
        self.path = None if path is None else Path(path)
        if self.path is not None and self.path.suffix != ".npz":
            self.path = self.path.with_name(self.path.name + ".npz")
        self.kind = kind
        self.label = kind if label is None else label
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
            The arrays and scalars given to `save` (scalars as 0-d arrays; string scalars as
            str).

        Raises
        ------
        ValueError
            One line naming the file: it is not a checkpoint of this label, has another
            format version, or belongs to a call with other inputs (the message names the
            differing fields).
        """
        if self.path is None or not self.path.exists():
            return None
        try:
            with np.load(self.path, allow_pickle=False) as data:
                state = {key: data[key] for key in data.files}
        except (OSError, ValueError, EOFError) as error:
            raise ValueError(f"{self.path}: not a readable {self.label} checkpoint "
                             f"({error})") from None
        if _SIGNATURE not in state or _VERSION not in state:
            if all(key in state for key in _OLD_JAM_KEYS):
                raise ValueError(f"{self.path}: a jam checkpoint of an older calippso, which "
                                 f"this version cannot resume; delete it to start afresh")
            raise ValueError(f"{self.path}: not a {self.label} checkpoint (no signature)")
        if int(state[_VERSION]) != FORMAT_VERSION:
            raise ValueError(f"{self.path}: checkpoint format {int(state[_VERSION])}, "
                             f"this version reads format {FORMAT_VERSION}")
        stored = str(state[_SIGNATURE])
        if stored != self.signature:
            raise ValueError(f"{self.path}: checkpoint of another run; it differs in "
                             f"{_differences(stored, self.signature)}. Use another path, or "
                             f"delete the file to start afresh")
        return {key: (str(value) if value.dtype.kind == "U" and value.ndim == 0 else value)
                for key, value in state.items() if not key.startswith("_")}

    def due(self) -> bool:
        """Whether a path was given and at least `every` seconds passed since the last save."""
        return self.path is not None and time.monotonic() - self._last >= self.every

    def maybe_save(self, state: dict) -> bool:
        """Save `state` if at least `every` seconds passed since the last save; return whether."""
        if not self.due():
            return False
        self.save(state)
        return True

    def save(self, state: dict) -> None:
        """Write `state` (arrays and scalars; keys not starting with "_") atomically."""
        if self.path is None:
            return
        arrays = {key: np.asarray(value) for key, value in state.items()}
        arrays[_SIGNATURE] = np.asarray(self.signature)
        arrays[_VERSION] = np.asarray(FORMAT_VERSION)
        save_npz_atomic(self.path, arrays)
        self._last = time.monotonic()


def _differences(stored: str, wanted: str) -> str:
    """Names of the signature fields that differ, for the error message."""
    a, b = json.loads(stored), json.loads(wanted)
    keys = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    return ", ".join(f"{k} (checkpoint {a.get(k)!r}, this call {b.get(k)!r})" for k in keys)
