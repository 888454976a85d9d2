"""The report's summary: the pooled analysis and one record per run
(`calippso.analysis.record.run_record`), as strict JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..analysis import Analysis
from ..analysis.exponents import REFERENCE_EXPONENTS
from ..analysis.record import run_record
from ..categories import CATEGORIES
from ..result import JammingResult

__all__ = ["category_counts", "fit_warnings", "run_record", "summary_dict",
           "write_json"]


def fit_warnings(analysis: Analysis) -> list[str]:
    """The warnings of the exponents fitted on too few values (`Exponent.warning`)."""
    return [e.warning for e in analysis.exponents.values() if e.warning]


def summary_dict(analysis: Analysis, results: list[JammingResult]) -> dict:
    """Everything the JSON summary holds, with the fit warnings under "warnings": the pooled
    analysis, then one record per run (`run_record`, plus its contact stress tensor as
    nested lists, None in a container) and the count of runs per jamming category."""
    runs = [{**run_record(r), "stress": _stress(r)} for r in results]
    return {**analysis.to_dict(), "reference_exponents": dict(REFERENCE_EXPONENTS),
            "warnings": fit_warnings(analysis), "runs": runs,
            "categories": category_counts(results)}


def category_counts(results: list[JammingResult]) -> dict[str, int]:
    """How many runs are in each jamming category ("not tested" for `category` None), in
    the order not tested, not jammed, local, collective, strict; absent categories left
    out."""
    order = ["not tested", *CATEGORIES]
    names = ["not tested" if r.category is None else r.category for r in results]
    return {name: names.count(name) for name in order if name in names}


def _stress(result: JammingResult) -> list[list[float]] | None:
    stress = result.contact_stress
    return None if stress is None else stress.tolist()


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
