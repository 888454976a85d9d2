"""Lazy, headless matplotlib: imported only when a figure is drawn."""

from __future__ import annotations

from types import ModuleType

__all__ = ["pyplot"]


def pyplot() -> ModuleType:
    """`matplotlib.pyplot` on the non-interactive Agg backend.

    Importing matplotlib is deferred to the first figure, and Agg draws to files without a
    display, so that reports and benchmark figures work on a headless machine.

    Returns
    -------
    ModuleType
        The module ``matplotlib.pyplot``, its backend switched to Agg.

    Raises
    ------
    ImportError
        matplotlib is missing; it is the optional extra ``plot``.
    """
    try:
        import matplotlib
    except ImportError as error:
        raise ImportError(
            "calippso reports draw their figures with matplotlib, which is not installed: "
            "pip install 'calippso[plot]' (or pip install matplotlib)") from error
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt
