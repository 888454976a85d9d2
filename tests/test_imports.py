"""Each scene loads only what it needs."""

import subprocess
import sys


def _modules_after(statement: str) -> set[str]:
    code = f"{statement}; import sys; print(' '.join(sorted(sys.modules)))"
    output = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True).stdout
    return {name.split(".")[0] for name in output.split()}


def test_import_calippso_is_light():
    loaded = _modules_after("import calippso; calippso.Packing; calippso.read")
    assert not loaded & {"numba", "highspy", "clarabel", "cvxpy", "matplotlib"}


def test_jam_loads_only_the_chosen_backend():
    loaded = _modules_after("import calippso; calippso.jam")
    assert "numba" not in loaded
    assert not loaded & {"highspy", "clarabel", "cvxpy"}  # backends load on first solve


def test_backend_names_are_checked_without_loading_a_backend():
    """Settings validate backend names against the registry, which imports no LP library."""
    loaded = _modules_after("from calippso.settings import JamSettings; "
                            "JamSettings(solver='clarabel', fallback_solvers=('cvxpy',))")
    assert not loaded & {"numba", "highspy", "clarabel", "cvxpy"}


def test_generators_stand_on_the_geometry_base_only():
    """The generators import calippso's geometry base, never the jamming core."""
    full = set(subprocess.run(
        [sys.executable, "-c", "import generators, sys; print(' '.join(sys.modules))"],
        capture_output=True, text=True, check=True).stdout.split())
    assert not full & {"highspy", "clarabel", "cvxpy"}
    core = {"calippso.ilp", "calippso.settings", "calippso.result", "calippso.solvers",
            "calippso.lp", "calippso.history", "calippso.network", "calippso.protocols",
            "calippso.ensemble"}
    assert not full & core, full & core


def test_protocols_load_the_generators_only_when_they_run():
    loaded = _modules_after("import calippso.protocols, calippso.ensemble")
    assert not loaded & {"numba", "generators", "highspy", "clarabel", "cvxpy"}
