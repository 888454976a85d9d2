"""The loop's state in a checkpoint (`calippso.checkpoint.Checkpoint`), and back.

`save_state` writes after every LP what the next LP depends on: the configuration, the
bound, the forced rows, the refused networks, the warm-start basis, the history and its
notes, and a deformable box's vectors. `resumed` reads it back, so that a resumed run takes the LPs the uninterrupted run
would have taken. `checkpoint_signature` is what the file belongs to.
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from ..atomic import digest
from ..checkpoint import Checkpoint
from ..history import HISTORY_COLUMNS
from ..geometry.packing import Packing
from ..settings import JamSettings
from ..solvers import Basis
from .state import LoopState, Run

__all__ = ["save_state", "resumed", "checkpoint_signature", "CHECKPOINT_FREE_SETTINGS"]

#: Settings that do not change the sequence of LPs, left out of a checkpoint's signature.
CHECKPOINT_FREE_SETTINGS = ("verbose", "max_iters", "time_limit")


def checkpoint_signature(packing: Packing, settings: JamSettings,
                         deformable: bool = False) -> dict:
    """What a jam checkpoint belongs to: a digest of the input and the settings that shape
    the sequence of LPs (all but `CHECKPOINT_FREE_SETTINGS`), and the box's mode when it is
    deformable (the digest then holds the box matrix)."""
    options = {name: value for name, value in asdict(settings).items()
               if name not in CHECKPOINT_FREE_SETTINGS}
    box = packing.lattice if deformable else packing.box
    signature = {"input": digest(packing.positions, packing.diameters, box), **options}
    if deformable:
        signature["box"] = "deformable"
    if not packing.boundaries.is_periodic:
        signature["boundaries"] = str(packing.boundaries)
    return signature


def save_state(checkpoint: Checkpoint | None, run: Run, state: LoopState) -> None:
    """Save the loop's state after an LP (nothing without a checkpoint)."""
    if checkpoint is None:
        return
    history = run.history.to_array()
    saved = {"positions": state.positions, "diameters": state.diameters, "step": state.step,
             "forced": state.forced,
             **({"forced_walls": state.forced_walls} if run.walled else {}),
             **({"cell": state.cell} if state.cell is not None else {}),
             "failed_networks": np.array(sorted(state.failed_networks), dtype=str),
             "notes": np.array(run.history.notes, dtype=str),
             **{f"history_{name}": history[name] for name in HISTORY_COLUMNS}}
    if state.basis is not None:
        saved.update(basis_row_keys=state.basis.row_keys,
                     basis_row_status=state.basis.row_status,
                     basis_col_status=state.basis.col_status)
    checkpoint.save(saved)


def resumed(run: Run, state: LoopState, saved: dict | None) -> LoopState:
    """The state saved by `save_state` (its history and notes restored into
    `run.history`), or `state` when nothing was saved."""
    if saved is None:
        return state
    run.history.restore({name: saved[f"history_{name}"] for name in HISTORY_COLUMNS},
                        saved["notes"].tolist())
    forced_walls = (saved["forced_walls"].astype(np.int64).reshape(-1, 2)
                    if "forced_walls" in saved else state.forced_walls)
    basis = (Basis(saved["basis_row_keys"], saved["basis_row_status"],
                   saved["basis_col_status"]) if "basis_row_keys" in saved else None)
    cell = saved["cell"] if "cell" in saved else None
    return LoopState(positions=saved["positions"], diameters=saved["diameters"],
                     search=(run.search(saved["positions"], saved["diameters"])
                             if cell is None else None),
                     step=float(saved["step"]),
                     forced=saved["forced"].astype(np.int64).reshape(-1, 2),
                     forced_walls=forced_walls, basis=basis,
                     failed_networks=frozenset(saved["failed_networks"].tolist()),
                     wall_kicks=state.wall_kicks, cell=cell)
