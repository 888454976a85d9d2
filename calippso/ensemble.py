"""Ensembles: many independent generate → jam → analyse runs, on local processes or Dask.

Every packing is one task, `make_one(spec, seed, state_dir)`, which makes its start
(`calippso.protocols.make_start`, then `calippso.protocols.precompress` if the spec asks for
it), jams it and sends back an `Outcome` (the arrays of the jammed packing, or the error). The calling
process writes every result file itself, as soon as each task comes back:
``out_dir/packing_<seed>.npz`` atomically (the full `JammingResult` plus the start's keys
``seed``, ``start_phi``, ``start_reduced_pressure``, ``generation_wall_time``), and
``out_dir/summary.csv`` (one row per packing, `COLUMNS`, with the run record of
`calippso.analysis.run_record`) after each finished task. Dask
workers therefore need no shared disk. Local workers also save the LS/MLS generator's and
the jamming loop's state in ``state_<seed>_start.npz`` and ``state_<seed>_jam.npz`` (and
the precompression's in ``state_<seed>_jam.precompress.npz``); a task
started again after a crash resumes from them, and they are removed once the packing is
written.

``out_dir/ensemble.json`` (`MANIFEST`) records the `EnsembleSpec` of the folder. A re-run
with the same spec skips every seed whose file exists (resume) and may add seeds; a re-run
with another spec is refused. A task that raises is recorded as a "failed" row, with its
traceback in ``packing_<seed>.error.txt``, and the other tasks go on (a failed seed is
retried by the next run).

Workers share Numba's on-disk cache of the generators: Numba writes its cache files through
a temporary file and a rename, so concurrent workers never read half a file; at worst
several cold workers compile the same function once each.
"""

from __future__ import annotations

import concurrent.futures
import csv
import io
import json
import multiprocessing
import os
import traceback
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .protocols import (DISTRIBUTIONS, PROTOCOLS, EnsembleSpec, make_diameters, make_start,
                        precompress, precompress_checkpoint)

__all__ = [
    "COLUMNS",
    "DISTRIBUTIONS",
    "EnsembleSpec",
    "MANIFEST",
    "Outcome",
    "PROTOCOLS",
    "SUMMARY",
    "check_manifest",
    "make_diameters",
    "make_one",
    "run",
    "run_on_scheduler",
    "run_one",
    "threads_per_worker",
    "limit_threads",
    "store",
    "summary_record",
]

#: Name of the summary table written in `out_dir`.
SUMMARY = "summary.csv"

#: Name of the file in `out_dir` that records the `EnsembleSpec` of its packings (JSON).
MANIFEST = "ensemble.json"

#: Columns of the summary table, in order: the seed, the state of the task, the file and the
#: start's numbers, then the run record (`calippso.analysis.record.RUN_RECORD_KEYS`) and the
#: error of a failed task.
COLUMNS = (
    "seed",
    "state",
    "file",
    "n",
    "d",
    "start_phi",
    "start_reduced_pressure",
    "generation_wall_time",
    "phi",
    "converged",
    "iterations",
    "isostatic",
    "isostaticity_gap",
    "n_contacts",
    "n_stable",
    "rattler_fraction",
    "n_bucklers",
    "force_balance",
    "min_gap",
    "wall_time",
    "solver",
    "status",
    "error",
)



def summary_record(result) -> dict:
    """Deprecated: `calippso.analysis.record.run_record`, the one record of a run."""
    warnings.warn("calippso.ensemble.summary_record is deprecated: use "
                  "calippso.analysis.run_record", DeprecationWarning, stacklevel=2)
    from .analysis.record import run_record

    return run_record(result)


def packing_file(out_dir: Path, seed: int) -> Path:
    """Where the jammed packing of `seed` is stored."""
    return Path(out_dir) / f"packing_{seed:06d}.npz"


def state_files(state_dir: Path, seed: int) -> tuple[Path, Path]:
    """The generator's and the jamming loop's state files of `seed` in `state_dir`."""
    return tuple(Path(state_dir) / f"state_{seed:06d}_{stage}.npz" for stage in ("start", "jam"))


@dataclass(frozen=True)
class Outcome:
    """What one task sends back: the arrays of the jammed packing, or why it failed.

    Attributes
    ----------
    seed : int
        The packing's seed.
    arrays : dict of str to numpy.ndarray, optional
        The ``.npz`` keys of the packing (`JammingResult.to_arrays` and the start's keys);
        None if the task failed.
    error : str
        One line, ``<ExceptionType>: <message>``, if the task failed.
    traceback : str
        The full traceback, if the task failed.
    """

    seed: int
    arrays: dict | None = None
    error: str = ""
    traceback: str = ""

    @classmethod
    def failed(cls, seed: int, error: BaseException) -> "Outcome":
        """The outcome of a task that raised `error`."""
        return cls(
            seed,
            error=" ".join(f"{type(error).__name__}: {error}".split()),
            traceback="".join(traceback.format_exception(error)),
        )


def make_one(spec: EnsembleSpec | dict, seed: int, state_dir: str | None = None) -> Outcome:
    """Generate and jam the packing of one seed; return it as an `Outcome`.

    Writes no result file, so it can run anywhere (a Dask worker without a shared disk).
    Never raises for a failing packing: the outcome then carries the error.

    Parameters
    ----------
    spec : EnsembleSpec or dict
        What the packing is.
    seed : int
        Its seed.
    state_dir : str, optional
        Folder for the state files of the generator and the jamming loop (`state_files`),
        resumed if they exist. None: no state files.
    """
    import calippso

    try:
        spec = EnsembleSpec.of(spec)
        start_state, jam_state = (None, None) if state_dir is None else state_files(state_dir, seed)
        made = make_start(spec, seed, checkpoint=start_state)
        start, seconds = made.packing, made.wall_time
        if spec.precompress is not None:
            compressed = precompress(start, spec.precompress,
                                     checkpoint=precompress_checkpoint(jam_state))
            start, seconds = compressed.packing, seconds + compressed.wall_time
        result = calippso.jam(start, solver=spec.solver, checkpoint=jam_state, **spec.jam_options)
    except Exception as error:  # a failing packing is recorded, the others go on
        return Outcome.failed(seed, error)
    extra = {
        "seed": np.array(seed),
        "start_phi": np.array(made.packing.phi),
        "start_reduced_pressure": np.array(float(made.reduced_pressure)),
        "generation_wall_time": np.array(seconds),
    }
    return Outcome(seed, arrays={**result.to_arrays(), **extra})


def store(out_dir: str | os.PathLike, outcome: Outcome) -> dict:
    """Write the outcome of one task into `out_dir`; return its summary row.

    A packing goes to ``packing_<seed>.npz`` (atomically), and its state files and any
    earlier error file are removed. A failure, or a packing that cannot be written, goes
    to ``packing_<seed>.error.txt`` (its traceback) and a row with ``state="failed"``.
    """
    from .atomic import save_npz_atomic

    out_dir = Path(out_dir)
    path = packing_file(out_dir, outcome.seed)
    error_file = path.with_suffix(".error.txt")
    if outcome.arrays is not None:
        try:
            save_npz_atomic(path, outcome.arrays)
        except Exception as error:  # e.g. a full disk: record the packing as failed
            outcome = Outcome.failed(outcome.seed, error)
        else:
            start_state, jam_state = state_files(out_dir, outcome.seed)
            for finished in (error_file, start_state, jam_state,
                             precompress_checkpoint(jam_state)):
                finished.unlink(missing_ok=True)
            return _row(outcome.arrays, outcome.seed, path.name)
    out_dir.mkdir(parents=True, exist_ok=True)
    error_file.write_text(outcome.traceback)
    return {"seed": outcome.seed, "state": "failed", "error": outcome.error}


def run_one(spec: EnsembleSpec | dict, seed: int, out_dir: str | os.PathLike) -> dict:
    """Generate, jam and analyse the packing of one seed in this process; write it into
    `out_dir` (`store`, with the state files there too); return its summary row."""
    return store(out_dir, make_one(spec, seed, str(out_dir)))


def _row(arrays, seed: int, name: str) -> dict:
    """The summary row of the packing whose ``.npz`` keys are `arrays`."""
    from .analysis.record import run_record
    from .result import JammingResult

    row = {"seed": seed, "state": "done", "file": name}
    row.update(run_record(JammingResult.from_arrays(arrays)))
    for key in ("start_phi", "start_reduced_pressure", "generation_wall_time"):
        row[key] = float(arrays[key]) if key in arrays else float("nan")
    return row


def _row_from_file(path: Path, seed: int) -> dict:
    """The summary row of the packing file `path`."""
    with np.load(path, allow_pickle=False) as data:
        return _row({key: data[key] for key in data.files}, seed, path.name)


def _spec_record(spec: EnsembleSpec) -> dict:
    """The spec as plain JSON values (what the manifest holds)."""
    return json.loads(json.dumps(asdict(spec), default=_plain))


def _plain(value):
    """A numpy scalar as a Python one, for `json.dumps`."""
    if hasattr(value, "item"):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def _read_manifest(path: Path) -> dict:
    try:
        return _spec_record(EnsembleSpec.of(json.loads(path.read_text())))
    except (ValueError, TypeError) as error:
        raise ValueError(f"{path}: not an ensemble manifest ({error})") from None


def _recorded_by_packings(out_dir: Path) -> dict:
    """n and d of a folder written before manifests existed, from one of its packings."""
    for path in sorted(out_dir.glob("packing_*.npz")):
        try:
            with np.load(path, allow_pickle=False) as data:
                n, d = data["positions"].shape
        except (OSError, ValueError, KeyError):
            continue  # unreadable: run will redo it
        return {"n": n, "d": d}
    return {}


def _write_manifest(path: Path, record: dict) -> None:
    """Write the manifest atomically (`atomic_path`: a new file gets the umask's permissions)."""
    from .atomic import atomic_path

    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")


def check_manifest(out_dir: Path, spec: EnsembleSpec) -> None:
    """Record `spec` in a new folder's manifest; refuse a folder made with another spec.

    Raises
    ------
    ValueError
        One line naming the folder and each differing parameter, ``old → new``.
    """
    path = Path(out_dir) / MANIFEST
    wanted = _spec_record(spec)
    recorded = _read_manifest(path) if path.is_file() else _recorded_by_packings(Path(out_dir))
    changed = [
        f"{name} {recorded[name]!r} → {wanted[name]!r}"
        for name in recorded
        if recorded[name] != wanted[name]
    ]
    if changed:
        raise ValueError(
            f"{out_dir} holds an ensemble with other parameters ({', '.join(changed)}): "
            "rerun with those or choose another folder"
        )
    if not path.is_file():
        _write_manifest(path, wanted)


def write_summary(out_dir: Path, rows: Iterable[dict]) -> Path:
    """Write the summary table (rows sorted by seed) atomically; return its path."""
    from .atomic import atomic_path

    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=COLUMNS, restval="", extrasaction="ignore")
    writer.writeheader()
    for row in sorted(rows, key=lambda row: row["seed"]):
        writer.writerow(row)
    path = Path(out_dir) / SUMMARY
    with atomic_path(path) as temporary:
        temporary.write_text(text.getvalue())
    return path


def _seeds(seeds: int | Iterable[int] | None, n_packings: int) -> list[int]:
    if seeds is None:
        seeds = 0
    if isinstance(seeds, (int, np.integer)):
        seeds = range(int(seeds), int(seeds) + n_packings)
    seeds = [int(seed) for seed in seeds]
    if len(seeds) != n_packings:
        raise ValueError(f"{len(seeds)} seeds for {n_packings} packings")
    if len(set(seeds)) != len(seeds) or min(seeds, default=0) < 0:
        raise ValueError("seeds must be distinct non-negative integers")
    return seeds


def threads_per_worker(workers: int) -> int:
    """The cores of this machine shared out among `workers` processes (at least 1 each)."""
    return max(1, (os.cpu_count() or 1) // max(1, workers))


def limit_threads(threads: int) -> None:
    """Give this process `threads` threads for Numba's parallel loops, BLAS and MKL.

    Run first in each worker process of the local pool, before the worker imports Numba or
    MKL (their thread counts are read from the environment when they load); BLAS, already
    loaded with numpy, is limited through `threadpoolctl`.
    """
    from threadpoolctl import threadpool_limits

    value = str(max(1, int(threads)))
    for variable in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                     "OPENBLAS_NUM_THREADS"):
        os.environ[variable] = value
    threadpool_limits(int(value))


def _is_dask(executor) -> bool:
    return type(executor).__module__.split(".")[0] == "distributed"


def run(
    spec: EnsembleSpec | dict,
    n_packings: int,
    *,
    seeds: int | Sequence[int] | None = None,
    out_dir: str | os.PathLike,
    executor=None,
    workers: int | None = None,
    threads: int | None = None,
    progress: bool = False,
) -> list[dict]:
    """Run an ensemble: one generate → jam → analyse task per seed, resuming earlier runs.

    Parameters
    ----------
    spec : EnsembleSpec or dict
        What each packing is.
    n_packings : int
        Number of packings.
    seeds : int or sequence of int, optional
        The seeds (one per packing), or the first of consecutive seeds (default 0).
    out_dir : str or PathLike
        Folder (of this process) for ``packing_<seed>.npz`` files, ``summary.csv`` and the
        manifest ``ensemble.json``; this process writes them all.
    executor : concurrent.futures.Executor or dask.distributed.Client, optional
        Where the tasks run. Default: a pool of `workers` local processes. Dask workers
        only compute and send the packings back; the workers of other executors also keep
        their state files in `out_dir`, so they must see it.
    workers : int, optional
        Size of the default local pool (default: the number of cores).
    threads : int, optional
        Threads of each worker of the default pool, for Numba's parallel loops, BLAS and
        MKL (`limit_threads`). Default: `threads_per_worker`, the cores shared out among
        the workers, so that workers × threads never exceeds the cores: oversubscribed
        threads spin-wait on each other's parallel regions.
    progress : bool
        Show a tqdm bar over packings.

    Returns
    -------
    list of dict
        One row per packing (`COLUMNS`), in seed order; ``state`` is "done" or "failed".
        The same rows are in ``out_dir/summary.csv``.

    Raises
    ------
    ValueError
        If `out_dir` holds an ensemble of another spec (`check_manifest`).
    """
    spec = EnsembleSpec.of(spec)
    if int(n_packings) < 1:
        raise ValueError(f"n_packings must be >= 1, got {n_packings}")
    seeds = _seeds(seeds, int(n_packings))
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    check_manifest(out_dir, spec)
    rows = {}
    for seed in seeds:
        path = packing_file(out_dir, seed)
        if path.is_file():
            try:
                rows[seed] = _row_from_file(path, seed)
            except (OSError, ValueError, KeyError):
                path.unlink()  # unreadable: run this seed again
    pending = [seed for seed in seeds if seed not in rows]
    write_summary(out_dir, rows.values())
    if pending:
        bar = _bar(progress, len(seeds), len(rows))
        owned = executor is None
        if owned:
            n_workers = min(workers or os.cpu_count() or 1, len(pending))
            executor = concurrent.futures.ProcessPoolExecutor(
                max_workers=n_workers, mp_context=multiprocessing.get_context("spawn"),
                initializer=limit_threads,
                initargs=(threads_per_worker(n_workers) if threads is None else threads,),
            )
        try:
            for outcome in _completed(executor, spec, pending, out_dir):
                rows[outcome.seed] = store(out_dir, outcome)
                write_summary(out_dir, rows.values())
                if bar is not None:
                    bar.update(1)
        finally:
            if owned:
                executor.shutdown(cancel_futures=True)
            if bar is not None:
                bar.close()
    return [rows[seed] for seed in seeds]


def _completed(executor, spec: EnsembleSpec, seeds: list[int], out_dir: Path):
    """Yield each task's `Outcome` as it finishes (a task lost with its worker: failed).

    Dask workers keep no state files (they may not see `out_dir`); other executors keep
    them in `out_dir`.
    """
    if _is_dask(executor):
        from distributed import as_completed

        futures = {
            executor.submit(make_one, asdict(spec), seed, None, pure=False): seed
            for seed in seeds
        }
    else:
        from concurrent.futures import as_completed

        state_dir = str(out_dir.resolve())
        futures = {
            executor.submit(make_one, asdict(spec), seed, state_dir): seed for seed in seeds
        }
    for future in as_completed(list(futures)):
        seed = futures.pop(future)  # dropping the future frees its result on the workers
        try:
            yield future.result()
        except Exception as error:  # the worker died: record it, go on with the others
            yield Outcome.failed(seed, error)


def _bar(enabled: bool, total: int, initial: int):
    if not enabled:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, initial=initial, desc="packings", unit=" packing")


def run_on_scheduler(
    spec: EnsembleSpec | dict,
    n_packings: int,
    *,
    address: str,
    seeds: int | Sequence[int] | None = None,
    out_dir: str | os.PathLike,
    progress: bool = False,
    timeout: float = 10.0,
) -> list[dict]:
    """`run` on the Dask cluster whose scheduler is at `address` (needs ``distributed``).

    The workers only compute; each packing comes back to this process, which writes it into
    `out_dir` (a folder of this process, relative to its working directory) as soon as it
    arrives, so the workers need no shared disk. `timeout` is the time allowed to connect,
    in seconds.

    Raises
    ------
    ImportError
        If ``distributed`` is not installed.
    ValueError
        If the scheduler cannot be reached, or as `run`.
    """
    try:
        from distributed import Client
    except ImportError:
        raise ImportError(
            "run_on_scheduler needs dask.distributed: pip install 'calippso[ensemble]'"
        ) from None
    try:
        client = Client(address, timeout=f"{timeout}s")
    except (OSError, TimeoutError) as error:
        raise ValueError(f"cannot reach the Dask scheduler at {address}: {error}") from None
    with client:
        return run(
            spec, n_packings, seeds=seeds, out_dir=out_dir, executor=client, progress=progress
        )
