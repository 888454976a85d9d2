"""HiGHS backend (highspy): vertex solutions, by interior point (IPX, or HiPO with the
highspy-extras package) + crossover, or by primal simplex warm-started from the previous LP's
basis; or, with ``crossover=False``, the interior solution itself (HiPO where installed,
IPX otherwise), the centre of the optimal face, read by `calippso.complementarity`.

HiGHS runs on the process's thread budget (`highs_threads`): HiPO factorises its Newton
systems in parallel (one LP at N = 16384, d = 3: 100 s on 2 threads, 175 s on 1); IPX and
the simplex run on one thread whatever the budget."""

from __future__ import annotations

import functools
import os
import time
from dataclasses import dataclass
from importlib.metadata import version

import highspy
import numpy as np

from ..c_stdout import c_stdout_to_devnull
from ..errors import SolverError
from ..lp import LinearProgram
from ..settings import JamSettings
from .base import Basis, LPSolution

#: With ``interior_point="auto"``, LPs with this many columns (d N + 1) or more are solved from
#: scratch by HiPO where it is installed: N ≥ 2048 in d = 3, N ≥ 1024 in d = 5, where whole
#: runs took about half as long with HiPO (docs/jamming.md, Backends). Smaller problems keep
#: IPX: there whole runs took as long or longer with HiPO, whose interior points lead the
#: crossover to other vertices and the loop along another path. The choice rests on the
#: columns, fixed for a run, and not on the rows, which grow and shrink with the step bound.
HIPO_MIN_COLUMNS = 5000
#: Relative duality gap of the interior solutions returned without crossover. At N = 16384
#: HiPO met it in 19 iterations, with duals and slacks that `calippso.complementarity` reads
#: apart.
INTERIOR_OPTIMALITY_TOLERANCE = 1e-12


@dataclass(frozen=True)
class HighsOptions:
    """Options of the HiGHS backend.

    Attributes
    ----------
    feasibility_tolerance : float
        HiGHS's primal and dual feasibility tolerances (rows are in mean diameters);
        ``JamSettings.feasibility_tolerance``.
    interior_point : {"auto", "ipx", "hipo"}
        The interior point of the LPs solved from scratch; ``JamSettings.interior_point``
        ("auto": `interior_point_for`).
    ipm_optimality_tolerance : float
        Relative duality gap at which the interior point hands over to the crossover.
    crossover : bool
        End every LP at a vertex (crossover after the interior point, or a warm-started
        simplex). False (``JamSettings.crossover="off"``): return the interior solution
        (no crossover, no warm start), at ``interior_optimality_tolerance``.
    interior_optimality_tolerance : float
        Relative duality gap at which an interior solution without crossover is returned.
    warm_iterations_per_row : float
        A warm-started primal simplex gives up after this many iterations per LP row (then
        interior point + crossover solves the LP); measured at N = 1024, d = 3, one
        interior-point solve costs about as much as 0.3 simplex iterations per row.
    min_warm_iterations : int
        ... but never after fewer than this many iterations.
    """

    feasibility_tolerance: float = 1e-10
    interior_point: str = "auto"
    ipm_optimality_tolerance: float = 1e-12
    crossover: bool = True
    interior_optimality_tolerance: float = INTERIOR_OPTIMALITY_TOLERANCE
    warm_iterations_per_row: float = 0.25
    min_warm_iterations: int = 200

    @classmethod
    def from_settings(cls, settings: JamSettings) -> "HighsOptions":
        """The options a run with `settings` uses (the other fields keep their defaults)."""
        return cls(feasibility_tolerance=settings.feasibility_tolerance,
                   interior_point=settings.interior_point,
                   crossover=settings.crossover != "off")


_STATUS = {int(v): v for v in (highspy.HighsBasisStatus.kLower, highspy.HighsBasisStatus.kBasic,
                               highspy.HighsBasisStatus.kUpper, highspy.HighsBasisStatus.kZero,
                               highspy.HighsBasisStatus.kNonbasic)}
_BASIC = int(highspy.HighsBasisStatus.kBasic)
#: HiGHS's ``simplex_strategy`` value for primal simplex.
_PRIMAL_SIMPLEX = 4


_banner_silenced = False
#: The environment variable that sets the process's thread budget (`highs_threads`), as it
#: does for OpenMP, BLAS and Numba (`calippso.ensemble.limit_threads` sets it in each
#: ensemble worker).
THREAD_BUDGET_VARIABLE = "OMP_NUM_THREADS"


def highs_threads() -> int:
    """The threads HiGHS may use: ``OMP_NUM_THREADS`` when it is set to a positive integer
    (an ensemble worker's share of the cores, `calippso.ensemble.limit_threads`), else the
    cores this process may run on. HiGHS's own default is half the cores."""
    budget = os.environ.get(THREAD_BUDGET_VARIABLE, "").strip()
    if budget.isdigit() and int(budget) > 0:
        return int(budget)
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:   # platforms without CPU affinity (macOS, Windows)
        return os.cpu_count() or 1


def _quiet_highs() -> highspy.Highs:
    """A `Highs` object with its output off, on `highs_threads` threads.

    highspy prints a banner to the C-level standard output when the first `Highs` object of
    the process is built, before any option can be set. That first construction runs with
    file descriptor 1 sent to the null device, so that `jam` writes nothing it was not asked
    to (the CLI may be writing results to standard output).
    """
    global _banner_silenced
    if _banner_silenced:
        highs = highspy.Highs()
    else:
        with c_stdout_to_devnull():
            highs = highspy.Highs()
        _banner_silenced = True
    highs.setOptionValue("output_flag", False)
    # the first run of the process starts HiGHS's thread pool with this many threads
    highs.setOptionValue("threads", highs_threads())
    return highs


def _set_interior_point(highs: highspy.Highs, name: str) -> None:
    """Select HiGHS's interior-point solver `name` ("ipx" or "hipo") on `highs`.

    Builds older than HiPO know only "ipm", which is IPX there. Where HiPO is installed, "ipm"
    means HiPO, so IPX is asked for by name.

    Raises
    ------
    ValueError
        If this HiGHS build refuses it (HiPO comes only with the highspy-extras package).
    """
    if highs.setOptionValue("solver", name) == highspy.HighsStatus.kOk:
        return
    if name == "ipx" and highs.setOptionValue("solver", "ipm") == highspy.HighsStatus.kOk:
        return
    raise ValueError(f'interior_point="{name}" is not available in this HiGHS build '
                     f'(highspy {version("highspy")}); HiPO needs the highspy-extras '
                     f'package: pip install "calippso[hipo]"')


def check_interior_point(name: str) -> None:
    """Raise ValueError, before any LP is built, if interior point `name` is not available."""
    _set_interior_point(_quiet_highs(), name)


@functools.lru_cache(maxsize=1)
def hipo_available() -> bool:
    """Whether this HiGHS build has HiPO (the highspy-extras package)."""
    try:
        check_interior_point("hipo")
    except ValueError:
        return False
    return True


def interior_point_for(lp: LinearProgram, setting: str) -> str:
    """The interior point that solves `lp` from scratch: `setting`, or for "auto" HiPO from
    `HIPO_MIN_COLUMNS` columns on when it is installed, IPX otherwise."""
    if setting != "auto":
        return setting
    return "hipo" if lp.n_cols >= HIPO_MIN_COLUMNS and hipo_available() else "ipx"


def highs_model(lp: LinearProgram, length_unit: float = 1.0) -> highspy.HighsLp:
    """The LP as a HiGHS model (minimise −γ; rows ≥ row_lower; the column bounds).

    Parameters
    ----------
    length_unit : float
        The unit of the model's lengths, in mean diameters. The LP is homogeneous in its
        variables (displacements and γ, `calippso.lp`): dividing the right-hand sides and
        the column bounds by a unit leaves the matrix, the optimum's rows and the duals as
        they are, and multiplies the solution by the unit's inverse. HiGHS's feasibility
        tolerances are absolute, so a unit of the step bound makes them resolve the gaps
        and the γ of an LP whose displacements are all within that bound.
    """
    model = highspy.HighsLp()
    model.num_col_ = lp.n_cols
    model.num_row_ = lp.n_rows
    model.sense_ = highspy.ObjSense.kMinimize
    cost = np.zeros(lp.n_cols)
    cost[-1] = -1.0
    model.col_cost_ = cost
    model.col_lower_ = lp.col_lower / length_unit
    model.col_upper_ = np.where(np.isinf(lp.col_upper), highspy.kHighsInf,
                                lp.col_upper / length_unit)
    model.row_lower_ = lp.row_lower / length_unit
    model.row_upper_ = np.full(lp.n_rows, highspy.kHighsInf)
    matrix = model.a_matrix_
    matrix.format_ = highspy.MatrixFormat.kColwise
    matrix.num_col_ = lp.n_cols
    matrix.num_row_ = lp.n_rows
    matrix.start_ = lp.matrix.indptr
    matrix.index_ = lp.matrix.indices
    matrix.value_ = lp.matrix.data
    return model


def _row_keys(lp: LinearProgram) -> np.ndarray:
    return lp.pairs.i.astype(np.int64) * lp.n + lp.pairs.j


def _basis_of(highs: highspy.Highs, lp: LinearProgram) -> Basis | None:
    basis = highs.getBasis()
    if not basis.valid:
        return None
    return Basis(_row_keys(lp), np.array([int(v) for v in basis.row_status], dtype=np.int8),
                 np.array([int(v) for v in basis.col_status], dtype=np.int8))


def mapped_basis(previous: Basis, lp: LinearProgram) -> highspy.HighsBasis | None:
    """The previous basis on this LP's rows: a row of the same pair keeps its status, a new
    row starts basic (inactive). None when the columns differ or the count of basic
    variables is not the number of rows (a dropped row was active)."""
    if previous.col_status.shape[0] != lp.n_cols:
        return None
    keys = _row_keys(lp)
    order = np.argsort(previous.row_keys)
    where = np.searchsorted(previous.row_keys, keys, sorter=order)
    where = order[np.minimum(where, order.shape[0] - 1)] if order.size else np.zeros_like(keys)
    found = previous.row_keys[where] == keys if order.size else np.zeros(keys.shape, bool)
    row_status = np.where(found, previous.row_status[where], _BASIC)
    n_basic = np.count_nonzero(row_status == _BASIC) + np.count_nonzero(
        previous.col_status == _BASIC)
    if n_basic != lp.n_rows:
        return None
    basis = highspy.HighsBasis()
    basis.col_status = [_STATUS[v] for v in previous.col_status]
    basis.row_status = [_STATUS[v] for v in row_status]
    basis.valid = True
    basis.alien = False   # a basis of this LP family: skip HiGHS re-factorising it in setBasis
    return basis


def _solution(highs: highspy.Highs, lp: LinearProgram, start: float,
              warm_started: bool, interior: bool = False,
              length_unit: float = 1.0) -> LPSolution:
    """The answer of `highs` to `lp`: a vertex with its basis, or an interior solution
    (`interior`: no basis, whatever HiGHS reports); `length_unit` is that of the model
    (`highs_model`), and the answer is in mean diameters."""
    status = highs.getModelStatus()
    info = highs.getInfo()
    solution = highs.getSolution()
    x = np.asarray(solution.col_value, dtype=np.float64) * length_unit
    duals = np.asarray(solution.row_dual, dtype=np.float64)  # ≥ 0 for active ≥ rows (minimising −γ)
    optimal = status == highspy.HighsModelStatus.kOptimal and x.shape[0] == lp.n_cols
    basis = None if interior else _basis_of(highs, lp)
    return LPSolution(x=x, duals=np.maximum(duals, 0.0) if duals.size else duals,
                      optimal=bool(optimal), status=highs.modelStatusToString(status),
                      seconds=time.perf_counter() - start, vertex=basis is not None,
                      solver="highs", basis=basis, warm_started=warm_started,
                      ipm_iterations=max(int(info.ipm_iteration_count), 0))


def solve(lp: LinearProgram, options: HighsOptions, warm_start: Basis | None = None
          ) -> LPSolution:
    """Solve with HiGHS at tight tolerances, returning a vertex solution.

    With `warm_start` (the optimal basis of the previous LP of the loop), primal simplex
    starts from that basis mapped onto this LP's rows; consecutive LPs of the loop differ
    little, so this takes a few hundred simplex iterations where interior point + crossover
    costs several times more. If the basis does not fit, or the simplex needs more than
    ``options.warm_iterations_per_row`` iterations per row, the LP is solved from scratch by
    interior point + crossover.

    Raises
    ------
    SolverError
        If HiGHS raised (out of memory, an internal error).
    """
    start = time.perf_counter()
    try:
        highs = _quiet_highs()
        highs.setOptionValue("primal_feasibility_tolerance", options.feasibility_tolerance)
        highs.setOptionValue("dual_feasibility_tolerance", options.feasibility_tolerance)
        if not options.crossover:
            return _interior_solution(highs, lp, options, start)
        highs.passModel(highs_model(lp))
        basis = mapped_basis(warm_start, lp) if warm_start is not None else None
        if basis is not None and highs.setBasis(basis) == highspy.HighsStatus.kOk:
            highs.setOptionValue("solver", "simplex")
            highs.setOptionValue("simplex_strategy", _PRIMAL_SIMPLEX)
            highs.setOptionValue("simplex_iteration_limit", max(
                options.min_warm_iterations, int(options.warm_iterations_per_row * lp.n_rows)))
            highs.run()
            if highs.getModelStatus() == highspy.HighsModelStatus.kOptimal:
                return _solution(highs, lp, start, warm_started=True)
            highs.clearSolver()
            highs.setOptionValue("simplex_iteration_limit", highspy.kHighsIInf)
        _set_interior_point(highs, interior_point_for(lp, options.interior_point))
        highs.setOptionValue("run_crossover", "on")
        highs.setOptionValue("ipm_optimality_tolerance", options.ipm_optimality_tolerance)
        highs.run()
    except (RuntimeError, MemoryError) as error:
        raise SolverError(f"HiGHS raised {type(error).__name__}: {error}") from error
    return _solution(highs, lp, start, warm_started=False)


def _interior_solution(highs: highspy.Highs, lp: LinearProgram, options: HighsOptions,
                       start: float) -> LPSolution:
    """Solve `lp` by interior point without crossover, from scratch, in units of its step
    bound (`highs_model`): the solver's absolute tolerances then resolve the gaps and the γ
    of an LP near convergence, which are many decades below a mean diameter.

    Raises RuntimeError or MemoryError as `highs` does (`solve` turns them into
    `SolverError`).
    """
    highs.passModel(highs_model(lp, length_unit=lp.step_bound))
    _set_interior_point(highs, interior_point_for(lp, options.interior_point))
    highs.setOptionValue("run_crossover", "off")
    # presolve would fix the columns no active row holds (rattlers) at a bound
    highs.setOptionValue("presolve", "off")
    highs.setOptionValue("ipm_optimality_tolerance", options.interior_optimality_tolerance)
    highs.run()
    return _solution(highs, lp, start, warm_started=False, interior=True,
                     length_unit=lp.step_bound)


class HighsBackend:
    """The "highs" backend (see `Backend`)."""

    name = "highs"
    options_type = HighsOptions

    def options(self, settings: JamSettings) -> HighsOptions:
        return HighsOptions.from_settings(settings)

    def validate(self, options: HighsOptions) -> None:
        """Raise ValueError if ``options.interior_point`` is "hipo" and this HiGHS build lacks
        it ("auto" takes HiPO only where it is installed; every build has IPX)."""
        if options.interior_point == "hipo":
            check_interior_point("hipo")

    def solve(self, lp: LinearProgram, options: HighsOptions,
              warm_start: Basis | None = None) -> LPSolution:
        return solve(lp, options, warm_start)


#: The registered instance (`calippso.solvers.registry`).
BACKEND = HighsBackend()
