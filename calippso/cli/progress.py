"""The LP progress bar of ``calippso jam`` and ``calippso demo``: one tick per LP."""

from __future__ import annotations

import sys


#: History stages that solve an LP: the ones `JammingResult.iterations` counts (the force
#: clean-up after the loop is one more LP).
LP_STAGES = frozenset({"lp", "cleanup"})
#: How the LP bar names each stage; a stage missing here is shown by its own name.
STAGE_LABELS = {"lp": "LP", "cleanup": "clean-up LP", "newton": "Newton",
                "guess": "network guess", "pivots": "pivots"}
#: The provisional record that a path of contact pivots hands the callback after each pivot.
PIVOT_STAGE = "pivot"


class LPProgress:
    """A tqdm bar over LPs showing the stage, √Γ − 1, max |s|, the contact count, the LP's
    rows and its interior-point iterations.

    It is a `jam` callback, called once per history record. Only the records of LP stages
    (`LP_STAGES`) tick the bar, so that its count is the number of LPs the summary reports;
    another stage (the Newton stage, the network guess) shows as the "stage" label beside
    its numbers. A path of contact pivots shows the pivots taken and the forces still
    non-positive as it goes. The bar appears with the first record, so input rejected
    before any LP prints no bar.
    """

    def __init__(self, enabled: bool, desc: str = "LP") -> None:
        self._enabled = enabled
        self._desc = desc
        self._bar = None
        self.lps = 0

    def __call__(self, record) -> None:
        if not self._enabled:
            return
        stage = str(record["stage"])
        self._show(record)
        if stage in LP_STAGES:
            self._tick(1)
        else:
            self._bar.refresh()

    def catch_up(self, history) -> None:
        """Count the LPs of a finished run that the callback never saw, and show its last record.

        The force clean-up LP runs after the loop, without a callback; the history of a run
        resumed from a checkpoint also holds the LPs solved before it.
        """
        if not self._enabled or not len(history):
            return
        self._show(history[-1])
        self._tick(sum(str(stage) in LP_STAGES for stage in history["stage"]) - self.lps)

    def _show(self, record) -> None:
        """Open the bar if needed and put the record's stage and numbers beside it."""
        if self._bar is None:
            from tqdm.auto import tqdm

            self._bar = tqdm(desc=self._desc, unit=" LP", file=sys.stderr)
        stage = str(record["stage"])
        if stage == PIVOT_STAGE:
            self._bar.set_postfix({"stage": "pivots", "pivots": int(record["pivots"]),
                                   "non-positive": int(record["non_positive"])},
                                  refresh=False)
            return
        self._bar.set_postfix(
            {
                "stage": STAGE_LABELS.get(stage, stage),
                "sqrt(G)-1": f"{record['sqrt_gamma_minus_1']:.1e}",
                "max|s|": f"{record['max_displacement']:.1e}",
                "contacts": int(record["n_contacts"]),
                "rows": int(record["rows"]),
                "IPM its": int(record["ipm_iterations"]),
            },
            refresh=False,
        )

    def _tick(self, lps: int) -> None:
        self.lps += lps
        self._bar.update(lps)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def jam_with_progress(packing, progress: bool, **options):
    """`calippso.jam` with an LP progress bar whose count is the result's number of LPs."""
    import calippso

    bar = LPProgress(progress)
    try:
        result = calippso.jam(packing, callback=bar, **options)
        bar.catch_up(result.history)
        return result
    finally:
        bar.close()
