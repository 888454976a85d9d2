"""`run_record`: the one flat description of a jamming run, shared by every summary.

The ensemble's ``summary.csv`` rows, the ``runs`` of a report's ``summary.json`` and the
``--json`` output of ``calippso jam`` all hold these keys (`RUN_RECORD_KEYS`).
"""

from __future__ import annotations

import numpy as np

from ..result import JammingResult
from ..geometry.touching import TOUCHING_GAP
from .forces import bucklers

__all__ = ["RUN_RECORD_KEYS", "run_record"]

#: The keys of `run_record`, in order, with their meaning.
RUN_RECORD_KEYS = {
    "n": "number of particles N",
    "d": "dimension d",
    "phi": "packing fraction of the jammed packing",
    "converged": "whether the run ended at a jamming point",
    "iterations": "number of LPs solved",
    "isostatic": "whether N_c = d (N_s - 1) + 1 (deformable box: d (N_s - 1) + d(d+1)/2)",
    "isostaticity_gap": "N_c less the isostatic count (0 when isostatic)",
    "n_contacts": "number of contacts N_c between stable particles",
    "n_stable": "number of stable (non-rattler) particles N_s",
    "n_touching": (f"pairs that touch (relative gap <= {TOUCHING_GAP:g}) outside the contact "
                   "network, stable pairs and particle-wall pairs: zero force, not in "
                   "n_contacts"),
    "rattler_fraction": "fraction of particles that are rattlers",
    "n_bucklers": "stable particles with exactly d + 1 contacts",
    "force_balance": "max over stable particles of |net force| / mean force",
    "box": "fixed (the box as given) or deformable (the box's strain in every LP)",
    "category": ("jamming category (not jammed, local, collective, strict) when tested, "
                 "else None"),
    "pressure": ("virial pressure tr(stress)/d of the contact forces (mean force 1, per unit "
                 "volume); None in a container"),
    "stress_anisotropy": ("max |stress - p I| / p of the contact stress (0 at a strictly "
                          "jammed point); None in a container"),
    "min_gap": "smallest relative gap |r|/sigma - 1 after the last stage (None without history)",
    "wall_time": "seconds from the call of jam to the verified result",
    "solver": "LP backend",
    "status": "one sentence on how the run ended",
}


def run_record(result: JammingResult) -> dict:
    """The numbers that describe one jamming run, as plain Python values (JSON- and CSV-ready).

    Parameters
    ----------
    result : JammingResult

    Returns
    -------
    dict
        The keys of `RUN_RECORD_KEYS`, in that order.
    """
    history = result.history
    return {
        "n": result.packing.n,
        "d": result.d,
        "phi": result.phi,
        "converged": bool(result.converged),
        "iterations": int(result.iterations),
        "isostatic": bool(result.isostatic),
        "isostaticity_gap": int(result.isostaticity_gap),
        "n_contacts": int(result.n_contacts),
        "n_stable": int(result.n_stable),
        "n_touching": len(result.touching),
        "rattler_fraction": float(result.rattler_fraction),
        "n_bucklers": int(np.count_nonzero(bucklers(result))),
        "force_balance": float(result.force_balance),
        "box": result.box_mode,
        "category": result.category,
        "pressure": _finite_or_none(result.pressure),
        "stress_anisotropy": _finite_or_none(result.stress_anisotropy),
        "min_gap": float(history["min_gap"][-1]) if history.shape[0] else None,
        "wall_time": float(result.wall_time),
        "solver": result.solver,
        "status": result.status,
    }


def _finite_or_none(value: float) -> float | None:
    """`value` as a float, or None when it is NaN (no stress)."""
    return float(value) if np.isfinite(value) else None
