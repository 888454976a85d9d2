"""Optional tqdm progress bar: nothing is printed unless the caller asks for it."""

from __future__ import annotations


class Progress:
    """A progress bar on a log-pressure scale, or a silent stand-in when `enabled` is False."""

    def __init__(self, enabled: bool, total: float, desc: str) -> None:
        self._bar = None
        if enabled:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=round(total, 2), desc=desc,
                             bar_format="{l_bar}{bar}| {n:.2f}/{total} [{elapsed}{postfix}]")

    def update(self, value: float, **postfix) -> None:
        """Set the bar to `value` (clipped to the total) and show `postfix` (e.g. φ, p)."""
        if self._bar is not None:
            self._bar.n = round(min(max(value, 0.0), self._bar.total), 2)
            self._bar.set_postfix(postfix, refresh=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
