"""Exceptions raised by the jamming core."""

from __future__ import annotations

import numpy as np

__all__ = ["JammingError", "SolverError"]


class SolverError(RuntimeError):
    """An LP backend failed (bad status, exception, or a solution that fails the checks)."""


class JammingError(RuntimeError):
    """`calippso.jam` could not finish.

    Attributes
    ----------
    packing : calippso.Packing or None
        The last valid (overlap-free, fully updated) configuration reached before the failure.
    history : ndarray, structured
        Records of the LPs that were solved before the failure.
    """

    def __init__(self, message: str, packing=None, history: np.ndarray | None = None):
        super().__init__(message)
        self.packing = packing
        self.history = history
