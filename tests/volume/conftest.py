"""Shared fixtures for the volume tests: where the real data sets live."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

_DEFAULT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "volumes"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """Folder of real volumes (``INTUITF_DATA``); tests that need it skip when it is absent."""
    d = Path(os.environ.get("INTUITF_DATA", _DEFAULT)).resolve()
    if not d.is_dir():
        pytest.skip(f"real volumes not found in {d} (set INTUITF_DATA)")
    return d
