"""The report's summary: the pooled analysis and one record per run, as strict JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..analysis import Analysis
from ..analysis.exponents import REFERENCE_EXPONENTS
from ..result import JammingResult

__all__ = ["fit_warnings", "run_record", "summary_dict", "write_json"]


def run_record(result: JammingResult) -> dict:
    """φ, contacts, isostaticity, convergence and timing of one run."""
    history = result.history
    return {
        "n": result.packing.n, "d": result.d, "phi": result.phi,
        "converged": bool(result.converged), "iterations": int(result.iterations),
        "solver": result.solver, "wall_time_s": float(result.wall_time),
        "stable": result.n_stable, "contacts": result.n_contacts,
        "rattler_fraction": result.rattler_fraction,
        "isostaticity_gap": result.isostaticity_gap, "force_balance": result.force_balance,
        "min_gap": float(history["min_gap"][-1]) if history.shape[0] else None,
        "status": result.status,
    }


def fit_warnings(analysis: Analysis) -> list[str]:
    """The warnings of the exponents fitted on too few values (`Exponent.warning`)."""
    return [e.warning for e in analysis.exponents.values() if e.warning]


def summary_dict(analysis: Analysis, results: list[JammingResult]) -> dict:
    """Everything the JSON summary holds, with the fit warnings under "warnings"."""
    return {**analysis.to_dict(), "reference_exponents": dict(REFERENCE_EXPONENTS),
            "warnings": fit_warnings(analysis), "runs": [run_record(r) for r in results]}


def _strict(value):
    """NaN and infinities become None (JSON has no such numbers); numpy scalars become Python."""
    if isinstance(value, dict):
        return {str(k): _strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(data: dict, path: Path) -> Path:
    """Write `data` as indented strict JSON (NaN written as null)."""
    path.write_text(json.dumps(_strict(data), indent=2, allow_nan=False) + "\n")
    return path
