"""Checkpoints of `jam`: the loop's state after every LP, saved atomically, and resumption.

With ``jam(..., checkpoint=path)`` the state of the CALiPPSO loop (positions, diameters, step
bound, pairs forced into the LP, networks the Newton stage rejected, history, notes and the
last LP's basis) is written to `path` after every LP, through a temporary file renamed into
place, so a run killed at any moment leaves the previous state or the new one, never a torn
file. A new call
with the same input, settings and path resumes from it; the LPs that follow are the ones the
uninterrupted run would have solved, so the result is the same bit for bit.

A checkpoint remembers what it belongs to (a digest of the input packing and of the
settings); a call with another input is refused with a ValueError instead of continuing
someone else's run.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .packing import Packing
from .atomic import save_npz_atomic
from .result import HISTORY_COLUMNS, history_from_records
from .settings import JamSettings
from .solvers.base import Basis

__all__ = ["digest", "signature", "save_state", "load_state"]

#: Version of the file layout; a file with another version is refused.
FORMAT_VERSION = 2
#: Settings that do not change the sequence of LPs, left out of the signature.
_IGNORED_SETTINGS = ("verbose", "max_iters")


def digest(*arrays: np.ndarray) -> str:
    """SHA-256 of the shapes and float64 bytes of `arrays`: identifies a configuration."""
    h = hashlib.sha256()
    for array in arrays:
        array = np.ascontiguousarray(array, dtype=np.float64)
        h.update(str(array.shape).encode())
        h.update(array.tobytes())
    return h.hexdigest()


def signature(packing: Packing, settings: JamSettings) -> str:
    """Digest of the input configuration and of the settings that shape the run."""
    options = {k: v for k, v in asdict(settings).items() if k not in _IGNORED_SETTINGS}
    h = hashlib.sha256(digest(packing.positions, packing.diameters, packing.box).encode())
    h.update(json.dumps(options, sort_keys=True, default=str).encode())
    return h.hexdigest()


def save_state(path: Path, key: str, state: dict) -> None:
    """Write the loop state atomically.

    Parameters
    ----------
    path : Path
        Checkpoint file (``.npz``).
    key : str
        `signature` of the run.
    state : dict
        "positions" (N, d), "diameters" (N,), "step" (float), "forced" (K, 2) int,
        "failed_networks" (list of str), "records" (list of history dicts), "notes" (list of
        str), "basis" (`calippso.solvers.Basis` or None: the warm start of the next LP), all
        in the loop's internal units.
    """
    arrays = {
        "format_version": np.array(FORMAT_VERSION),
        "signature": np.array(key),
        "positions": state["positions"],
        "diameters": state["diameters"],
        "step": np.array(state["step"]),
        "forced": np.asarray(state["forced"], dtype=np.int64).reshape(-1, 2),
        "failed_networks": np.array(sorted(state["failed_networks"]), dtype=str),
        "notes": np.array(state["notes"], dtype=str),
    }
    basis = state.get("basis")
    if basis is not None:
        arrays.update(basis_row_keys=basis.row_keys, basis_row_status=basis.row_status,
                      basis_col_status=basis.col_status)
    history = history_from_records(state["records"])
    for name in HISTORY_COLUMNS:
        arrays[f"history_{name}"] = history[name]
    save_npz_atomic(path, arrays)


def load_state(path: Path, key: str) -> dict | None:
    """The state saved at `path` for the run with signature `key`, or None if there is none.

    Raises
    ------
    ValueError
        The file is not a jam checkpoint, has another layout version, or belongs to another
        input or other settings.
    """
    if not os.path.exists(path):
        return None
    try:
        data = dict(np.load(path, allow_pickle=False))
    except (OSError, ValueError) as error:
        raise ValueError(f"checkpoint {path} cannot be read: {error}") from error
    if "signature" not in data or "format_version" not in data:
        raise ValueError(f"{path} is not a jam checkpoint")
    if int(data["format_version"]) != FORMAT_VERSION:
        raise ValueError(f"checkpoint {path} has layout version {int(data['format_version'])}, "
                         f"this calippso reads version {FORMAT_VERSION}")
    if str(data["signature"]) != key:
        raise ValueError(f"checkpoint {path} belongs to another input or other jam settings; "
                         f"delete it or pass another path")
    n_records = data["history_wall_time"].shape[0]
    records = [{name: data[f"history_{name}"][k].item() for name in HISTORY_COLUMNS}
               for k in range(n_records)]
    return {
        "positions": data["positions"],
        "diameters": data["diameters"],
        "step": float(data["step"]),
        "forced": data["forced"].astype(np.int64).reshape(-1, 2),
        "failed_networks": set(data["failed_networks"].tolist()),
        "records": records,
        "notes": data["notes"].tolist(),
        "basis": (Basis(data["basis_row_keys"], data["basis_row_status"],
                        data["basis_col_status"]) if "basis_row_keys" in data else None),
    }
