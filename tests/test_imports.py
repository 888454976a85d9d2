"""Each scene loads only what it needs."""

import ast
import subprocess
import sys
from pathlib import Path


def _modules_after(statement: str) -> set[str]:
    code = f"{statement}\nimport sys; print(' '.join(sorted(sys.modules)))"
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
    """jam checks every backend name against the registry, which imports no LP library,
    before it imports the chosen backend."""
    loaded = _modules_after(
        "from calippso.settings import JamSettings; "
        "from calippso.solvers.policy import prepare_backends\n"
        "try: prepare_backends(JamSettings(solver='clarabel', fallback_solvers=('gurobi',)))\n"
        "except ValueError as error: assert \"fallback solver 'gurobi'\" in str(error)")
    assert not loaded & {"numba", "highspy", "clarabel", "cvxpy"}


#: The calippso modules the generators may import: the geometry base, and the rattler rule.
GEOMETRY_BASE = {"calippso", "calippso.geometry", "calippso.geometry.packing",
                 "calippso.geometry.boundaries", "calippso.geometry.periodic",
                 "calippso.geometry.neighbors", "calippso.geometry.rattlers", "calippso.atomic",
                 "calippso.checkpoint"}
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


#: The packages whose import graph must have no cycle.
PACKAGES = ("calippso", "generators")


def _module_names(root: Path) -> dict[str, Path]:
    """Dotted name -> source file of every module of `PACKAGES` (a package by its name)."""
    names = {}
    for package in PACKAGES:
        for path in (root / package).rglob("*.py"):
            parts = path.relative_to(root).with_suffix("").parts
            names[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return names


def _imported_modules(name: str, path: Path, known: set[str]) -> set[str]:
    """The modules of `known` that module `name` (source `path`) imports, relative imports
    resolved; ``from package import module`` counts the module, ``from package import
    name`` the package."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    imported = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            imported |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module
            if node.level:
                parent = package[:len(package) - node.level + 1]
                base = ".".join(parent + ([node.module] if node.module else []))
            imported |= {f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base
                         for alias in node.names}
    return (imported & known) - {name}


def _a_cycle(graph: dict[str, set[str]]) -> list[str]:
    """One cycle of `graph` as a list of modules (the first repeated at the end), or []."""
    state: dict[str, str] = {}   # "open" while on the depth-first path, then "done"
    path: list[str] = []

    def visit(module: str) -> list[str]:
        state[module] = "open"
        path.append(module)
        for target in sorted(graph[module]):
            if state.get(target) == "open":
                return path[path.index(target):] + [target]
            if target not in state and (cycle := visit(target)):
                return cycle
        state[module] = "done"
        path.pop()
        return []

    for module in sorted(graph):
        if module not in state and (cycle := visit(module)):
            return cycle
    return []


def test_a_cycle_is_found():
    assert _a_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a", "b", "c", "a"]
    assert _a_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) == []


def test_the_import_graph_has_no_cycle():
    """No import cycle inside calippso and generators, read from the source with `ast`.

    Every import statement counts: module-level ones, the lazy ones inside functions and
    the ones under ``if TYPE_CHECKING:``. A lazy or type-only import still says that one
    module needs another; a cycle through it puts two modules on each other's layer, so
    neither can be read, tested or moved alone, and a lazy import is one refactoring away
    from a circular import error. Not counted: a submodule's implicit import of its parent
    package, and modules loaded through `importlib` (calippso's lazy top-level attributes,
    the backend registry's module paths), which are strings, not import statements.
    """
    root = Path(__file__).resolve().parents[1]
    modules = _module_names(root)
    graph = {name: _imported_modules(name, path, set(modules))
             for name, path in modules.items()}
    assert {"calippso.settings", "calippso.solvers.policy"} <= graph["calippso.ilp"]
    assert "calippso.settings" in graph["calippso.solvers.backend"]   # under TYPE_CHECKING
    cycle = _a_cycle(graph)
    assert not cycle, " -> ".join(cycle)
