"""Lazy, headless matplotlib: imported only when a figure is drawn."""

from __future__ import annotations

__all__ = ["pyplot"]


def pyplot():
    """`matplotlib.pyplot` on the non-interactive Agg backend.

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
