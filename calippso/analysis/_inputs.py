"""One validation helper for every analysis entry point: a result or a sequence of results."""

from __future__ import annotations

from collections.abc import Iterable

from ..result import JammingResult

__all__ = ["as_results"]


def as_results(results: JammingResult | Iterable[JammingResult]) -> list[JammingResult]:
    """Return `results` as a non-empty list of `JammingResult` of a single dimension.

    Parameters
    ----------
    results : JammingResult or iterable of JammingResult
        One jammed packing, or an ensemble to be pooled.

    Raises
    ------
    TypeError
        An element is not a `JammingResult`.
    ValueError
        The sequence is empty, or the packings do not all have the same dimension.
    """
    items = [results] if isinstance(results, JammingResult) else list(results)
    if not items:
        raise ValueError("results is empty: pass one JammingResult or a non-empty sequence")
    for k, item in enumerate(items):
        if not isinstance(item, JammingResult):
            raise TypeError(f"results[{k}] is a {type(item).__name__}, expected JammingResult")
    dimensions = sorted({item.d for item in items})
    if len(dimensions) > 1:
        raise ValueError(f"cannot pool packings of different dimensions: d = {dimensions}")
    return items
