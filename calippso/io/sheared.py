"""The one-line refusal of a sheared box by the formats that hold only a rectangular one."""

from __future__ import annotations

__all__ = ["refuse_sheared"]


def refuse_sheared(packing, format_name: str) -> None:
    """Raise ValueError when `packing` (a `Packing`) has a sheared box (`box_matrix`):
    `format_name` holds only box side lengths; .npz and .h5 keep the box matrix."""
    if getattr(packing, "box_matrix", None) is not None:
        raise ValueError(f"{format_name} holds a rectangular box only, this packing's box is "
                         f"sheared (box_matrix): write .npz or .h5 instead")
