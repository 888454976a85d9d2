"""The history of one `calippso.jam` run, in one place.

One `Record` per stage of the run: every LP of the loop ("lp"), the force clean-up LP
("cleanup"), every contact network guessed from the input ("guess"), every path of contact
pivots that reached a jamming point ("pivots") and every certified Newton stage ("newton").
`History` keeps them in order with the run's notes (what was repaired, retried or tried),
prints them when verbose, and stores them as the structured array `JammingResult.history`.
`StopReason` says why the loop stopped, and `status_sentence` turns it, the last step and
the notes into the one sentence users read.

Notes that name one LP and differ only in their numbers ("LP 12 converged with a hypostatic
network ... (gap -1): ...", written again at LP 15 with gap -2) are folded into one, where
the first stood: "LPs 12-15 (2 times) converged with a hypostatic network ... (gap -2 to
-1): ...", with the count, the range of LPs and the range of every other number.
"""

from __future__ import annotations

import enum
import re
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace

import numpy as np

from .geometry.contacts import isostaticity_gap

__all__ = ["StopReason", "Record", "History", "HISTORY_COLUMNS", "HISTORY_DTYPE",
           "empty_history", "history_from_records", "status_sentence", "reason_from_status",
           "STALL_LPS", "fold_note"]

#: The loop stops as stalled (not converged) after this many LPs without progress
#: (`History.stalled`).
STALL_LPS = 25
#: `History.stalled` compares the displacements of this many first and last LPs of the window.
STALL_ENDS = 5

#: Columns of `JammingResult.history` (a numpy structured array, one record per stage:
#: every LP, the Newton stage if it ran, and the force clean-up LP if one was needed).
HISTORY_COLUMNS: dict[str, tuple[object, str]] = {
    "stage": ("U8", "'guess' (a contact network read from the input, before any LP), "
                    "'lp', 'pivots' (contact pivots from a network with non-positive forces), "
                    "'newton' (contact equations solved and certified) or 'cleanup'"),
    "wall_time": (np.float64, "seconds since the call to jam, at the end of this iteration"),
    "solver_time": (np.float64, "seconds inside the LP solver for this iteration, retried and "
                                "discarded attempts included"),
    "sqrt_gamma_minus_1": (np.float64, "√Γ* − 1, the relative diameter growth of this LP"),
    "max_displacement": (np.float64, "max |s_iμ| over non-rattlers, in mean diameters"),
    "rows": (np.int64, "pair constraints (rows) in the LP"),
    "step_bound": (np.float64, "bound on each displacement component, in mean diameters"),
    "n_contacts": (np.int64, "contacts among non-rattlers after this LP"),
    "isostaticity_gap": (np.int64, "N_c − (d N_s + 1 − zero modes) after this LP"),
    "force_balance": (np.float64, "max |Σ f n| / mean force over stable particles"),
    "min_gap": (np.float64, "smallest h_ij = |r_ij|/σ_ij − 1 after the update"),
    "phi": (np.float64, "packing fraction after the update"),
    "pivots": (np.int64, "contact pivots taken in this stage (0 but in a 'pivots' record)"),
    "ipm_iterations": (np.int64, "interior-point iterations of this LP (0 for a warm-started "
                                 "simplex, and for the stages that solve no LP)"),
}

#: The structured dtype of `JammingResult.history` (fields `HISTORY_COLUMNS`).
HISTORY_DTYPE = np.dtype([(name, dtype) for name, (dtype, _) in HISTORY_COLUMNS.items()])


class StopReason(enum.Enum):
    """Why `calippso.jam` stopped. The first four end at a jamming point (``converged``)."""

    #: An LP met the tolerances: √Γ − 1 < tol_gamma and max |s| < tol_s over stable
    #: particles, with the step bound limiting nothing.
    CONVERGED = "converged"
    #: The Newton stage solved the contact equations of an LP's isostatic network and its
    #: certificate proved the jamming point; the loop ended there, without another LP.
    CERTIFIED_NEWTON = "certified_newton"
    #: The input's own contact network was certified by the Newton stage, with no LP.
    NETWORK_FIRST = "network_first"
    #: Contact pivots (`calippso.certification.pivots`) took a network whose jamming point had
    #: non-positive forces (the input's own, or an LP's) to a jamming point, which the
    #: Newton certificate proved.
    CERTIFIED_PIVOTS = "certified_pivots"
    #: An LP met the tolerances, but no rigid contact network holds the packing: every
    #: particle is a rattler, or the network is hypostatic (a packing with a floppy motion,
    #: or a crystal whose forces the LP left on too few contacts). Not a jamming point.
    NOT_RIGID = "not_rigid"
    #: ``max_iters`` LPs were solved without convergence.
    MAX_ITERS = "max_iters"
    #: The last `STALL_LPS` LPs gained nothing in Γ and their displacements did not shrink.
    STALLED = "stalled"
    #: The callback returned True.
    STOPPED_BY_CALLBACK = "stopped_by_callback"
    #: ``time_limit`` seconds had passed after an LP or a Newton stage; the checkpoint, if
    #: any, resumes the run.
    TIME_LIMIT = "time_limit"

    @property
    def jammed(self) -> bool:
        """Whether the run ended at a jamming point (`JammingResult.converged`)."""
        return self in (StopReason.CONVERGED, StopReason.CERTIFIED_NEWTON,
                        StopReason.NETWORK_FIRST, StopReason.CERTIFIED_PIVOTS)


@dataclass(frozen=True)
class Record:
    """One stage of a run; the fields are the `HISTORY_COLUMNS` (same names, units and
    meaning). Lengths are in mean input diameters."""

    stage: str
    wall_time: float
    solver_time: float
    sqrt_gamma_minus_1: float
    max_displacement: float
    rows: int
    step_bound: float
    n_contacts: int
    isostaticity_gap: int
    force_balance: float
    min_gap: float
    phi: float
    pivots: int = 0
    ipm_iterations: int = 0

    def as_dict(self) -> dict:
        """The record as a dict (what ``jam(..., callback=...)`` receives, with more keys)."""
        return asdict(self)


class History:
    """The records and notes of one run, in order.

    Parameters
    ----------
    d : int
        Dimension (for the isostaticity gaps).
    start : float
        `time.perf_counter()` at the call to `jam`: records' wall times count from it.
    verbose : bool
        Print every record as it is added (a table with a header line).
    zero_modes : int, optional
        Rigid motions the container leaves free (`Boundaries.zero_modes`); None: d.
    """

    def __init__(self, d: int, start: float, verbose: bool = False,
                 zero_modes: int | None = None) -> None:
        self.d = d
        self.zero_modes = d if zero_modes is None else zero_modes
        self.start = start
        self.verbose = verbose
        self.records: list[Record] = []
        self.notes: list[str] = []

    # ------------------------------------------------------------------ adding
    def note(self, text: str) -> None:
        """Add a note: a clause of the status sentence, and an entry of `JammingResult.notes`.
        A note that repeats an earlier one for another LP is folded into it (`fold_note`)."""
        self.notes = fold_note(self.notes, text)

    def add_lp(self, *, stage: str, solver_time: float, gamma: float, max_displacement: float,
               rows: int, step_bound: float, n_contacts: int, n_stable: int,
               force_balance: float, min_gap: float, phi: float,
               ipm_iterations: int = 0) -> Record:
        """The record of an LP ("lp" or "cleanup"); `gamma` is the LP's Γ* − 1."""
        return self._add(Record(
            stage=stage, wall_time=self.elapsed(), solver_time=solver_time,
            sqrt_gamma_minus_1=float(np.sqrt(1.0 + gamma) - 1.0),
            max_displacement=max_displacement, rows=rows, step_bound=step_bound,
            n_contacts=n_contacts,
            isostaticity_gap=isostaticity_gap(n_contacts, n_stable, self.d, self.zero_modes),
            force_balance=force_balance, min_gap=min_gap, phi=phi,
            ipm_iterations=ipm_iterations))

    def add_newton(self, *, seconds: float, sqrt_gamma_minus_1: float,
                   max_displacement: float, n_contacts: int, n_stable: int,
                   force_balance: float, min_gap: float, phi: float) -> Record:
        """The record of a certified Newton stage (no step bound; rows are the contacts)."""
        return self._add(Record(
            stage="newton", wall_time=self.elapsed(), solver_time=seconds,
            sqrt_gamma_minus_1=sqrt_gamma_minus_1, max_displacement=max_displacement,
            rows=n_contacts, step_bound=float("nan"), n_contacts=n_contacts,
            isostaticity_gap=isostaticity_gap(n_contacts, n_stable, self.d, self.zero_modes),
            force_balance=force_balance, min_gap=min_gap, phi=phi))

    def add_pivots(self, *, seconds: float, pivots: int, sqrt_gamma_minus_1: float,
                   max_displacement: float, n_contacts: int, n_stable: int, min_gap: float,
                   phi: float) -> Record:
        """The record of a path of contact pivots, to a jamming point or to where its budget
        ran out (rows are the contacts of its last network; growth and move from the path's
        start)."""
        return self._add(Record(
            stage="pivots", wall_time=self.elapsed(), solver_time=seconds,
            sqrt_gamma_minus_1=sqrt_gamma_minus_1, max_displacement=max_displacement,
            rows=n_contacts, step_bound=float("nan"), n_contacts=n_contacts,
            isostaticity_gap=isostaticity_gap(n_contacts, n_stable, self.d, self.zero_modes),
            force_balance=float("nan"), min_gap=min_gap, phi=phi, pivots=pivots))

    def add_guess(self, *, seconds: float, rows: int, n_contacts: int, n_stable: int,
                  min_gap: float, phi: float) -> Record:
        """The record of a guessed contact network (nothing moves; rows are its pairs)."""
        return self._add(Record(
            stage="guess", wall_time=self.elapsed(), solver_time=seconds,
            sqrt_gamma_minus_1=0.0, max_displacement=0.0, rows=rows,
            step_bound=float("nan"), n_contacts=n_contacts,
            isostaticity_gap=isostaticity_gap(n_contacts, n_stable, self.d, self.zero_modes),
            force_balance=float("nan"), min_gap=min_gap, phi=phi))

    def correct_min_gap(self, min_gap: float) -> None:
        """Replace the last record's `min_gap` (after a final round-off shrink)."""
        self.records[-1] = replace(self.records[-1], min_gap=min_gap)

    def elapsed(self) -> float:
        """Seconds since the call to `jam` (a resumed run counts the time before)."""
        return time.perf_counter() - self.start

    def _add(self, record: Record) -> Record:
        self.records.append(record)
        if self.verbose:
            print_record(record, len(self.records))
        return record

    # ------------------------------------------------------------------ reading
    @property
    def last(self) -> Record:
        """The last record."""
        return self.records[-1]

    @property
    def lps_solved(self) -> int:
        """LPs solved so far (records of the LP loop and of the force clean-up)."""
        return sum(record.stage in ("lp", "cleanup") for record in self.records)

    def last_step(self) -> Record:
        """The loop's last step: the last record that is not the force clean-up LP (whose
        step is never taken)."""
        return [record for record in self.records if record.stage != "cleanup"][-1]

    def stalled(self, tol_gamma: float) -> bool:
        """The last `STALL_LPS` LPs gained less than `tol_gamma` in √Γ − 1 and the largest
        displacements of their last `STALL_ENDS` are no smaller than half of their first."""
        lps = [record for record in self.records if record.stage == "lp"][-STALL_LPS:]
        if len(lps) < STALL_LPS:
            return False
        steps = [record.max_displacement for record in lps]
        return (max(record.sqrt_gamma_minus_1 for record in lps) < tol_gamma
                and min(steps[-STALL_ENDS:]) >= 0.5 * min(steps[:STALL_ENDS]))

    # ------------------------------------------------------------------ storage
    def to_array(self) -> np.ndarray:
        """The records as a structured array with the `HISTORY_COLUMNS` fields."""
        return history_from_records([record.as_dict() for record in self.records])

    def restore(self, columns: Mapping[str, np.ndarray], notes: list[str]) -> None:
        """Continue from stored records and notes (a checkpoint); wall times go on from the
        last record's.

        Parameters
        ----------
        columns : mapping of str to ndarray, shape (records,)
            One array per `HISTORY_COLUMNS` name (`to_array` or its columns).
        notes : list of str
        """
        self.records = [Record(**{name: columns[name][k].item() for name in HISTORY_COLUMNS})
                        for k in range(len(columns["stage"]))]
        self.notes = list(notes)
        if self.records:
            self.start -= self.records[-1].wall_time


#: The LP a note names ("LP 12"), or the LPs of a folded note ("LPs 3-40 (20 times)",
#: "LP 7 (2 times)").
_LP_MENTION = re.compile(r"\bLPs? (\d+)(?:-(\d+))?(?: \((\d+) times\))?")
#: A number in a note, or the range of a folded note's numbers ("-3 to -1").
_NUMBER = r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?"
_VALUE = re.compile(rf"(?<![\w.])({_NUMBER})(?: to ({_NUMBER}))?(?![\w.])")
#: Stands for the LP mention in the form of a note.
_MENTION_MARK = "\0"


@dataclass(frozen=True)
class _Fold:
    """A note naming LPs, taken apart: its words (`form`, the text between its numbers, the
    LP mention marked), the LPs it covers and the range of each of its other numbers (as
    written)."""

    form: tuple[str, ...]
    first: int
    last: int
    count: int
    values: tuple[tuple[str, str], ...]

    @classmethod
    def parse(cls, text: str) -> "_Fold | None":
        """The note taken apart, or None when it names no single LP (or LP range)."""
        mentions = list(_LP_MENTION.finditer(text))
        if len(mentions) != 1:
            return None
        mention = mentions[0]
        first = int(mention.group(1))
        last = int(mention.group(2) or first)
        count = int(mention.group(3) or 1)
        rest = text[:mention.start()] + _MENTION_MARK + text[mention.end():]
        pieces = _VALUE.split(rest)   # words, then (low, high or None) per number
        form = tuple(pieces[::3])
        values = tuple((low, high or low) for low, high in zip(pieces[1::3], pieces[2::3]))
        return cls(form, first, last, count, values)

    def merged(self, other: "_Fold") -> "_Fold":
        """The fold of both (same `form`)."""
        values = tuple((min(a[0], b[0], key=float), max(a[1], b[1], key=float))
                       for a, b in zip(self.values, other.values))
        return _Fold(self.form, min(self.first, other.first), max(self.last, other.last),
                     self.count + other.count, values)

    def text(self) -> str:
        if self.count == 1:
            mention = f"LP {self.first}"
        elif self.first == self.last:
            mention = f"LP {self.first} ({self.count} times)"
        else:
            mention = f"LPs {self.first}-{self.last} ({self.count} times)"
        numbers = [low if float(low) == float(high) else f"{low} to {high}"
                   for low, high in self.values]
        words = [piece for pair in zip(self.form, [*numbers, ""]) for piece in pair]
        return "".join(words).replace(_MENTION_MARK, mention)


def fold_note(notes: list[str], text: str) -> list[str]:
    """`notes` with `text` added: folded into the earlier note that has the same words and
    names another LP (or the same), appended otherwise.

    Parameters
    ----------
    notes : list of str
        The notes so far (folded ones included, so that a resumed run folds on).
    text : str
        The new note.

    Returns
    -------
    list of str
        A new list; a folded note keeps the place of the first of its notes, with the
        count of its notes, the range of their LPs and the range of every other number.
    """
    new = _Fold.parse(text)
    if new is not None:
        for k, note in enumerate(notes):
            old = _Fold.parse(note)
            if old is not None and old.form == new.form:
                return [*notes[:k], old.merged(new).text(), *notes[k + 1:]]
    return [*notes, text]


def empty_history() -> np.ndarray:
    """A history array with no records (dtype with the `HISTORY_COLUMNS` fields)."""
    return np.zeros(0, dtype=HISTORY_DTYPE)


def history_from_records(records: list[dict]) -> np.ndarray:
    """Build the structured history array from a list of per-stage dicts (`Record.as_dict`)."""
    history = np.zeros(len(records), dtype=HISTORY_DTYPE)
    for k, record in enumerate(records):
        for name in HISTORY_COLUMNS:
            history[name][k] = record[name]
    return history


def print_record(record: Record, number: int) -> None:
    """Print one record as a table row (after the header, for the first one)."""
    if number == 1:
        print(f"{'#':>4} {'stage':>7} {'rows':>8} {'sqrtG-1':>9} {'max|s|':>9} {'bound':>8} "
              f"{'Nc':>7} {'iso':>5} {'balance':>8} {'min gap':>9} {'phi':>12} {'LP s':>7} "
              f"{'total s':>8}")
    print(f"{number:4d} {record.stage:>7} {record.rows:8d} {record.sqrt_gamma_minus_1:9.2e} "
          f"{record.max_displacement:9.2e} {record.step_bound:8.1e} {record.n_contacts:7d} "
          f"{record.isostaticity_gap:5d} {record.force_balance:8.1e} {record.min_gap:9.2e} "
          f"{record.phi:12.9f} {record.solver_time:7.2f} {record.wall_time:8.2f}", flush=True)


#: How `status_sentence` begins for each reason (`reason_from_status` reads them back).
_HEADS = {
    StopReason.NETWORK_FIRST: "Jammed: the input's own contact network certified, with no LP",
    StopReason.CONVERGED: "Jammed: converged after {lps} LPs",
    StopReason.CERTIFIED_NEWTON: "Jammed: converged after {lps} LPs",
    StopReason.CERTIFIED_PIVOTS: "Jammed: reached by contact pivots after {lps} LPs",
    StopReason.NOT_RIGID: ("Not jammed: the LPs converged after {lps} LPs, but no rigid contact "
                           "network holds the packing"),
    StopReason.STOPPED_BY_CALLBACK: "Stopped by the callback after {lps} LPs",
    StopReason.TIME_LIMIT: "Stopped at the time limit after {lps} LPs",
    StopReason.STALLED: ("Stalled after {lps} LPs: the last {stall} gained nothing in Gamma "
                         "and their displacements did not shrink"),
    StopReason.MAX_ITERS: "Not converged after {lps} LPs (max_iters)",
}


def status_sentence(reason: StopReason, lps_solved: int, last_step: Record, n_stable: int,
                    isostaticity_gap: int, notes: list[str]) -> str:
    """The one sentence on how a run ended: why it stopped, its last step, the network, and
    the notes.

    Parameters
    ----------
    reason : StopReason
    lps_solved : int
        LPs of the run (`JammingResult.iterations`).
    last_step : Record
        The loop's last step (`History.last_step`): a Newton stage is quoted by its own move.
    n_stable : int
        Stable particles of the final network.
    isostaticity_gap : int
        N_c − d (N_s − 1) − 1 of the final network.
    notes : list of str
        Appended after "Notes:", separated by semicolons.
    """
    if n_stable == 0:
        tail = "no stable particle (every particle is a rattler)"
    elif isostaticity_gap == 0:
        tail = "isostatic"
    else:
        kind = "hyperstatic" if isostaticity_gap > 0 else "hypostatic"
        tail = f"{kind} (isostaticity gap {isostaticity_gap:+d})"
    if last_step.stage == "newton":
        # the Newton stage's own move: the certificate, not the tolerances, ends the run
        step = (f"the Newton stage moved stable particles by up to "
                f"{last_step.max_displacement:.1e} and grew the diameters by "
                f"sqrt(Gamma)-1 = {last_step.sqrt_gamma_minus_1:.1e}")
    else:
        step = (f"sqrt(Gamma)-1 = {last_step.sqrt_gamma_minus_1:.1e}, "
                f"max|s| = {last_step.max_displacement:.1e}")
    head = _HEADS[reason].format(lps=lps_solved, stall=STALL_LPS)
    sentence = f"{head} ({step}); {tail}."
    if notes:
        sentence += " Notes: " + "; ".join(notes) + "."
    return sentence


def reason_from_status(status: str, last_stage: str) -> StopReason | None:
    """The `StopReason` of a status sentence written by `status_sentence` (result files saved
    before results stored their reason), or None when the sentence says none.

    Parameters
    ----------
    status : str
    last_stage : str
        Stage of the run's last record that is not "cleanup": a run that converged with a
        Newton stage last counts as `StopReason.CERTIFIED_NEWTON`.
    """
    for reason, head in _HEADS.items():
        if status.startswith(head.split("{")[0]):
            if reason is StopReason.CONVERGED and last_stage == "newton":
                return StopReason.CERTIFIED_NEWTON
            return reason
    return None
