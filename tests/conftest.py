"""Shared fixtures: paths to the real input packings in ../shared/data."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The folder of real packings made by other codes (skips the test if absent)."""
    if not SHARED_DATA.is_dir():
        pytest.skip("../shared/data is not beside this checkout")
    return SHARED_DATA


import sys

sys.path.insert(0, str(Path(__file__).resolve().parent))  # tests/configurations.py
