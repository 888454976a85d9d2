"""Each scene loads only what it needs."""

import ast
import subprocess
import sys
from pathlib import Path


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


#: The calippso modules the generators may import: the geometry base, and the rattler rule.
GEOMETRY_BASE = {"calippso", "calippso.packing", "calippso.periodic", "calippso.neighbors",
                 "calippso.atomic", "calippso.checkpoint", "calippso.rattlers"}
#: Imported by the spherocylinder pictures only, when one is drawn (the shared renderer).
PICTURES = {"calippso.reporting"}


def test_generators_stand_on_the_geometry_base_only():
    """Importing the generators loads calippso's geometry base, never the jamming core."""
    full = set(subprocess.run(
        [sys.executable, "-c", "import generators, sys; print(' '.join(sys.modules))"],
        capture_output=True, text=True, check=True).stdout.split())
    assert not full & {"highspy", "clarabel", "cvxpy", "scipy.optimize"}
    calippso_modules = {name for name in full if name.split(".")[0] == "calippso"}
    assert calippso_modules <= GEOMETRY_BASE, calippso_modules - GEOMETRY_BASE


def _calippso_imports(path: Path) -> set[str]:
    """The calippso modules a source file imports, inside functions too."""
    imported = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            imported |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            imported.add(node.module)
            if node.module == "calippso":   # from calippso import periodic
                imported |= {f"calippso.{alias.name}" for alias in node.names}
    return {name for name in imported if name.split(".")[0] == "calippso"}


def test_generators_source_imports_only_the_geometry_base():
    """Every import in the generators' source, the ones made on first use included."""
    root = Path(__file__).resolve().parents[1] / "generators"
    outside = {f"{path.relative_to(root.parent)}: {name}"
               for path in root.rglob("*.py")
               for name in _calippso_imports(path) - GEOMETRY_BASE - PICTURES}
    assert not outside, sorted(outside)


def test_protocols_load_the_generators_only_when_they_run():
    loaded = _modules_after("import calippso.protocols, calippso.ensemble")
    assert not loaded & {"numba", "generators", "highspy", "clarabel", "cvxpy"}
