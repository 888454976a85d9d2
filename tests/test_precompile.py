"""`generators.precompile` fills an empty Numba cache with every kernel the generators use."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

#: Generator runs of the kind users start with: every generator and container in d = 3, at
#: sizes and options other than the warm-up's.
USER_RUNS = [
    ["ls", "--n", "96", "--pressure", "1e3"],
    ["ls", "--n", "96", "--pressure", "1e3", "--walls", "x", "--d", "2"],
    ["ls", "--n", "96", "--pressure", "1e3", "--cylinder", "x,y"],
    ["fb", "--n", "96", "--walls", "x,y"],
    ["quench", "--n", "96"],
    ["quench", "--n", "96", "--cylinder", "x,y"],
    ["mls", "--n", "96", "--d", "2"],
]


def _cache_files(folder: Path) -> dict[str, tuple[int, int]]:
    """Every Numba index and machine-code file under `folder`, with its size and mtime."""
    return {str(path.relative_to(folder)): (path.stat().st_size, path.stat().st_mtime_ns)
            for path in folder.rglob("*") if path.suffix in (".nbi", ".nbc")}


@pytest.mark.slow
def test_user_runs_after_precompile_compile_nothing(tmp_path):
    """After `python -m generators.precompile` into an empty cache (~1 min), the generator
    runs of `USER_RUNS` load every kernel from it: no index or machine-code file is added or
    rewritten."""
    cache = tmp_path / "numba"
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    subprocess.run([sys.executable, "-m", "generators.precompile"], env=environment,
                   check=True, capture_output=True)
    compiled = _cache_files(cache)
    assert compiled
    for number, arguments in enumerate(USER_RUNS):
        output = tmp_path / f"run{number}.npz"
        subprocess.run([sys.executable, "-m", "calippso", "generate", *arguments,
                        "-o", str(output)], env=environment, check=True, capture_output=True)
        assert output.exists()
    assert _cache_files(cache) == compiled
