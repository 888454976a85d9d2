"""`calippso.history`: records, the stop reason, and the status sentence built from them."""

from __future__ import annotations

import numpy as np
import pytest

from calippso.history import STALL_LPS, History, StopReason, reason_from_status, status_sentence

STEP = dict(solver_time=0.1, rows=10, step_bound=1e-3, n_contacts=7, n_stable=3,
            force_balance=0.0, min_gap=0.0, phi=0.5)


def test_only_the_first_four_reasons_are_jammed():
    jammed = {reason for reason in StopReason if reason.jammed}
    assert jammed == {StopReason.CONVERGED, StopReason.CERTIFIED_NEWTON,
                      StopReason.NETWORK_FIRST, StopReason.CERTIFIED_PIVOTS}


@pytest.mark.parametrize("reason", list(StopReason))
def test_the_reason_is_read_back_from_its_status(reason):
    """Result files saved before `stop_reason` existed get it from their status sentence."""
    history = History(d=2, start=0.0)
    if reason in (StopReason.NETWORK_FIRST, StopReason.CERTIFIED_NEWTON,
                  StopReason.CERTIFIED_PIVOTS):
        history.add_newton(seconds=0.1, sqrt_gamma_minus_1=1e-9, max_displacement=1e-8,
                           n_contacts=7, n_stable=4, force_balance=0.0, min_gap=0.0, phi=0.8)
    else:
        history.add_lp(stage="lp", gamma=1e-3, max_displacement=1e-2, **STEP)
    status = status_sentence(reason, history.lps_solved, history.last_step(), 4, 0, [])
    assert reason_from_status(status, history.last_step().stage) is reason
    assert reason_from_status("", "lp") is None


def test_a_history_stalls_when_lps_gain_nothing_and_steps_do_not_shrink():
    history = History(d=2, start=0.0)
    for _ in range(STALL_LPS - 1):
        history.add_lp(stage="lp", gamma=0.0, max_displacement=1e-3, **STEP)
    assert not history.stalled(tol_gamma=1e-12)
    history.add_lp(stage="lp", gamma=0.0, max_displacement=1e-3, **STEP)
    assert history.stalled(tol_gamma=1e-12)
    shrinking = History(d=2, start=0.0)
    for k in range(STALL_LPS):
        shrinking.add_lp(stage="lp", gamma=0.0, max_displacement=0.5**k, **STEP)
    assert not shrinking.stalled(tol_gamma=1e-12)


def test_records_round_trip_through_the_history_array():
    history = History(d=3, start=0.0)
    history.note("a note")
    history.add_lp(stage="lp", gamma=1e-3, max_displacement=1e-2, **STEP)
    history.add_guess(seconds=0.2, rows=9, n_contacts=7, n_stable=3, min_gap=1e-9, phi=0.6)
    history.correct_min_gap(2e-16)
    array = history.to_array()
    again = History(d=3, start=10.0)
    again.restore({name: array[name] for name in array.dtype.names}, history.notes)
    for name in array.dtype.names:   # column by column: NaN bounds compare equal
        np.testing.assert_array_equal(again.to_array()[name], array[name])
    assert again.notes == ["a note"]
    assert again.records[-1].min_gap == 2e-16 and again.lps_solved == 1


def _kick(lp: int, what: str = "converged", gap: int = -1) -> str:
    return (f"LP {lp} {what} with a hypostatic network in a container (gap {gap:+d}): the loop "
            f"went on from a fresh step bound")


def test_repeated_notes_fold_into_one_with_a_count_and_the_range_of_lps():
    history = History(d=3, start=0.0)
    history.note("network first: the input holds no isostatic contact network")
    for lp in range(3, 23):
        history.note(_kick(lp, gap=-1 - lp % 2))
    history.note("3 pair(s) outside the LP overlapped after LP 23; re-solved with them")
    history.note(_kick(24, what="grew sqrt(Gamma) by 3.2e-10"))
    history.note(_kick(25, what="grew sqrt(Gamma) by 9.0e-11"))
    assert history.notes == [
        "network first: the input holds no isostatic contact network",
        "LPs 3-22 (20 times) converged with a hypostatic network in a container "
        "(gap -2 to -1): the loop went on from a fresh step bound",
        "3 pair(s) outside the LP overlapped after LP 23; re-solved with them",
        "LPs 24-25 (2 times) grew sqrt(Gamma) by 9.0e-11 to 3.2e-10 with a hypostatic "
        "network in a container (gap -1): the loop went on from a fresh step bound"]


def test_a_single_note_and_notes_without_an_lp_are_kept_as_written():
    history = History(d=3, start=0.0)
    for text in [_kick(4), "contact equations solved by Newton after 12 LPs; certified",
                 "contact equations solved by Newton after 12 LPs; certified"]:
        history.note(text)
    assert history.notes == [_kick(4), *["contact equations solved by Newton after 12 LPs; "
                                         "certified"] * 2]


def test_a_resumed_history_folds_on_from_its_folded_notes():
    history = History(d=3, start=0.0)
    for lp in (5, 9):
        history.note(_kick(lp))
    resumed = History(d=3, start=0.0)
    resumed.restore({name: np.zeros(0) for name in history.to_array().dtype.names},
                    history.notes)
    resumed.note(_kick(3, gap=+1))
    resumed.note(_kick(3, gap=+1))
    assert resumed.notes == ["LPs 3-9 (4 times) converged with a hypostatic network in a "
                             "container (gap -1 to +1): the loop went on from a fresh step "
                             "bound"]
