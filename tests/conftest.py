"""Shared fixtures and the physics every jammed result must satisfy.

`assert_jammed` is the one definition of "jammed" the tests use: no overlap beyond
`OVERLAP_TOLERANCE` σ, an isostatic network N_c = d (N_s − 1) + 1, force balance within
`BALANCE_TOLERANCE`, positive forces; all recomputed here from the returned geometry,
independently of the loop. Input makers live in `configurations.py` and `lattices.py`.
"""

from __future__ import annotations

import copyreg
import hashlib
import os
import pickle
import sys
from pathlib import Path

#: Each pytest-xdist worker computes on one thread: the workers share the cores, and two
#: workers whose Numba, BLAS and MKL threads compete for 2 cores spin-wait each other's
#: parallel regions (a soft-quench test module took 7 s alone and 290 s beside another).
#: Set before numpy loads its BLAS; Numba's threads in `pytest_configure`. The threaded
#: kernels are still compared against one thread in test_generators_soft_quench.py.
WORKER_THREADS = 1
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_variable, str(WORKER_THREADS))

#: Subprocesses that the tests start (the CLI, the examples, import checks) import this
#: checkout, as the tests themselves do: an installed copy beside it would be a second copy of
#: the generators, whose kernels Numba would compile and cache a second time.
REPOSITORY = Path(__file__).resolve().parents[1]
os.environ["PYTHONPATH"] = os.pathsep.join(
    [str(REPOSITORY), *filter(None, [os.environ.get("PYTHONPATH")])])

import numpy as np  # noqa: E402
import pytest  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))  # configurations.py, lattices.py

from calippso.geometry.packing import Packing, minimum_image  # noqa: E402
from configurations import overlap_free  # noqa: E402

SHARED_DATA = REPOSITORY.parent / "shared" / "data"

#: Largest overlap accepted in a result, relative to σ_ij.
OVERLAP_TOLERANCE = 1e-12
#: Largest net force on a stable particle (forces normalised to mean 1).
BALANCE_TOLERANCE = 1e-12
#: A contact's relative gap |h| = |r_ij / σ_ij − 1| stays below this.
CONTACT_GAP_TOLERANCE = 1e-9
#: Σ λ_ij σ_ij² = 1 (the LP's dual normalisation) to this absolute tolerance.
NORMALIZATION_TOLERANCE = 1e-10


def pytest_configure(config) -> None:
    """In a pytest-xdist worker, Numba's parallel loops run on `WORKER_THREADS` threads. In
    the controller of a run with workers, the generators' kernels are compiled and cached
    first, once, split over the cores (`generators.precompile`): otherwise each worker
    compiles the same kernels beside the other on a fresh install."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        import numba

        numba.set_num_threads(WORKER_THREADS)
    elif getattr(config.option, "numprocesses", None) and not config.option.collectonly:
        from generators.precompile import precompile

        precompile()


@pytest.fixture
def replace_backend(monkeypatch):
    """``replace_backend(backend)`` registers `backend` under its name for the test only (in
    place of the backend of that name, if any; see `calippso.solvers.register_backend`)."""
    from calippso.solvers import registry

    def replace(backend) -> None:
        monkeypatch.setitem(registry._REGISTRY, backend.name, backend)

    return replace


@pytest.fixture(scope="session")
def nearly_jammed():
    """Case 1 of the extreme matrix: an N = 128, d = 3 LS packing at p = 1e12, its contacts
    closed to ~1e-12 σ without overlap."""
    from configurations import ls_packing

    packing = ls_packing(128, 3, seed=1)
    assert 0 <= overlap_free(packing) < 1e-9
    return packing


@pytest.fixture(scope="session")
def mls_jammed():
    """The MLS (closest-jamming) run of `configurations.mls_start` with `MLS_ARGS`, made once
    for the session (~4 s)."""
    import generators
    from configurations import MLS_ARGS, mls_start

    return generators.closest_jamming(start=mls_start(), **MLS_ARGS)


@pytest.fixture(scope="session")
def ls_jammed():
    """An LS packing at p = 1e7 (d = 3, N = 64) jammed by the LP path (no network first)."""
    import generators
    from calippso import jam

    sizes = generators.diameters.monodisperse(64)
    start = generators.lubachevsky_stillinger(sizes, d=3, target_pressure=1e7, seed=3).packing
    result = jam(start, network_first="off")
    assert_jammed(result)
    return result


class _Pickler(pickle.Pickler):
    """Pickles a `Packing` as a call of its constructor, so that the copy read back has the
    read-only arrays of every Packing (a plain pickle gives writable ones)."""

    dispatch_table = {**copyreg.dispatch_table,
                      Packing: lambda p: (Packing, (p.positions, p.diameters, p.box,
                                                    p.boundaries, p.box_matrix))}


@pytest.fixture(scope="session")
def computed_once(tmp_path_factory):
    """``computed_once(name, compute)``: the value of ``compute()``, computed by the first
    pytest-xdist worker that asks for `name` and read back from a file by the others.

    For the expensive module fixtures: a module's tests may run in both workers (the work
    stealing splits modules), and each worker would compute the fixture again. Without
    workers (or without ``fcntl``), ``compute()`` runs here.
    """
    try:
        import fcntl
    except ImportError:
        fcntl = None
    if not os.environ.get("PYTEST_XDIST_WORKER") or fcntl is None:
        return lambda name, compute: compute()
    folder = tmp_path_factory.getbasetemp().parent   # shared by the workers of this run

    def once(name: str, compute):
        path = folder / f"computed_once_{name}.pickle"
        with open(folder / f"computed_once_{name}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if path.is_file():
                return pickle.loads(path.read_bytes())
            value = compute()
            with open(path.with_suffix(".partial"), "wb") as stream:
                _Pickler(stream, protocol=pickle.HIGHEST_PROTOCOL).dump(value)
            path.with_suffix(".partial").replace(path)
            return value

    return once


@pytest.fixture(scope="session")
def quenched_discs():
    """512 equal discs soft-quenched to p = 1e-6 (d = 2, seed 2; ~2 s): they crystallise in
    patches, and no rigid network holds them (test_extremes, test_c_stdout)."""
    import generators

    return generators.soft_quench(generators.diameters.monodisperse(512), 2, seed=2,
                                  target_pressure=1e-6)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The folder of real packings made by other codes (skips the test if absent)."""
    if not SHARED_DATA.is_dir():
        pytest.skip("../shared/data is not beside this checkout")
    return SHARED_DATA


# ----------------------------------------------------------------------------- invariants

def jam_digest(result) -> str:
    """SHA-256 of everything a jam computes (wall and solver times left out)."""
    h = hashlib.sha256()
    for array in (result.packing.positions, result.packing.diameters, result.packing.box,
                  result.contacts, result.forces, result.rattlers):
        h.update(np.ascontiguousarray(array).tobytes())
    history = result.history
    for name in history.dtype.names:
        if name not in ("wall_time", "solver_time"):
            h.update(np.ascontiguousarray(history[name]).tobytes())
    h.update(repr((result.converged, result.iterations, result.force_balance,
                   result.dual_normalization)).encode())
    return h.hexdigest()


def net_forces(result) -> np.ndarray:
    """Net contact force on every particle, recomputed from the returned geometry, (N, d)."""
    packing = result.packing
    i, j = result.contacts.T
    delta = minimum_image(packing.positions[i] - packing.positions[j], packing.box)
    normals = delta / np.linalg.norm(delta, axis=1)[:, None]
    net = np.zeros((packing.n, packing.d))
    np.add.at(net, i, result.forces[:, None] * normals)
    np.add.at(net, j, -result.forces[:, None] * normals)
    return net


def assert_contacts_touch(result) -> None:
    """Every contact joins two stable particles (i < j) that touch: |h| < CONTACT_GAP_TOLERANCE."""
    packing = result.packing
    i, j = result.contacts.T
    assert np.all(i < j)
    assert not result.rattlers[i].any() and not result.rattlers[j].any()
    delta = minimum_image(packing.positions[i] - packing.positions[j], packing.box)
    sigma = 0.5 * (packing.diameters[i] + packing.diameters[j])
    gaps = np.linalg.norm(delta, axis=1) / sigma - 1
    assert np.max(np.abs(gaps), initial=0.0) < CONTACT_GAP_TOLERANCE


def assert_rigid_and_balanced(result) -> None:
    """Converged, overlap-free (brute force over all pairs), real contacts, positive forces of
    mean 1 in balance on every particle, Σ λ σ² = 1, every stable particle with ≥ d + 1
    contacts; isostatic or hyperstatic."""
    packing = result.packing
    assert result.converged, result.status
    assert overlap_free(packing) >= -OVERLAP_TOLERANCE
    assert_contacts_touch(result)
    assert np.all(result.forces > 0)
    assert result.forces.mean() == pytest.approx(1.0, rel=1e-12)
    assert np.abs(net_forces(result)).max(initial=0.0) <= BALANCE_TOLERANCE
    assert result.force_balance <= BALANCE_TOLERANCE
    assert result.dual_normalization == pytest.approx(1.0, abs=NORMALIZATION_TOLERANCE)
    counts = np.bincount(result.contacts.ravel(), minlength=packing.n)
    assert np.all(counts[~result.rattlers] >= packing.d + 1)
    assert result.isostaticity_gap >= 0, result.status
    lp_stages = np.isin(result.history["stage"], ["lp", "cleanup"])
    assert result.iterations == np.count_nonzero(lp_stages)


def assert_jammed(result) -> None:
    """A jammed, isostatic packing: `assert_rigid_and_balanced` and N_c = d (N_s − 1) + 1
    with more than d + 1 stable particles."""
    assert_rigid_and_balanced(result)
    packing = result.packing
    n_stable = int(np.count_nonzero(~result.rattlers))
    assert n_stable > packing.d + 1, result.status
    assert result.n_contacts == packing.d * (n_stable - 1) + 1, result.status
    assert result.isostatic and result.isostaticity_gap == 0


def kill_after_saved_lps(call: str, checkpoint: Path, lps: int, poll: float = 0.05) -> None:
    """Run `call` (Python source that jams with ``checkpoint=``, the tests' helpers on its
    path) in a child process and kill it with SIGKILL once its checkpoint holds `lps` LPs.

    Raises AssertionError when the run ends (or 300 s pass) before it could be killed.
    """
    import signal
    import subprocess
    import time

    tests = Path(__file__).resolve().parent
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(tests), str(tests.parent), os.environ.get("PYTHONPATH", "")])}
    process = subprocess.Popen([sys.executable, "-c", call], env=env,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and process.poll() is None:
            if checkpoint.exists():
                with np.load(checkpoint) as saved:
                    if saved["history_phi"].shape[0] >= lps:
                        break
            time.sleep(poll)
        assert process.poll() is None, "the run ended before it could be killed"
        process.send_signal(signal.SIGKILL)
        process.wait()
    finally:
        if process.poll() is None:
            process.kill()
