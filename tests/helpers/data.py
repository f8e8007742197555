"""Where the real volumes live: ``$INTUITF_DATA``, defaulting to ``../shared/data/volumes``."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

_DEFAULT = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "volumes"

#: The folder of real volumes (it may not exist: tests that need it skip).
DATA = Path(os.environ.get("INTUITF_DATA", _DEFAULT)).resolve()


def data_dir() -> Path | None:
    """The folder of real volumes, or None when it is absent."""
    return DATA if DATA.is_dir() else None


def data_file(name: str) -> Path:
    """The path of real volume ``name``; skips the calling test when it is not there."""
    p = DATA / name
    if not p.exists():
        pytest.skip(f"test volume {name} not found in {DATA} (set INTUITF_DATA)")
    return p
