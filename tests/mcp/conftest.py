"""Fixtures of the MCP tests: the server's folders with a small copy of the CT foot, the fake
model server, a finished run to act on, and clients of the SDK (in memory and over stdio)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcp_util import FOOT_SIZE

from helpers.data import data_file


@pytest.fixture(scope="session")
def small_foot_file(tmp_path_factory) -> Path:
    """The CT foot downsampled to 48³ and written as raw uint8 (its name gives shape and type),
    so that every server opens it in milliseconds."""
    from intuitf.volume import load_volume

    vol = load_volume(data_file("foot_zfp8lossy_256x256x256_uint8.raw.gz"), max_dim=FOOT_SIZE)
    folder = tmp_path_factory.mktemp("mcp-data")
    nx, ny, nz = vol.dims
    path = folder / f"foot_{nx}x{ny}x{nz}_uint8.raw"
    lo, hi = vol.value_range
    raw = np.clip(np.rint(lo + vol.data * (hi - lo)), 0, 255).astype(np.uint8)
    path.write_bytes(raw.tobytes())  # data[z, y, x]: x fastest, as the raw reader expects
    return path


@pytest.fixture
def folders(tmp_path, small_foot_file) -> dict[str, Path]:
    """--data (the foot, and a link that points outside it), --runs and --out of one server."""
    data = tmp_path / "data"
    data.mkdir()
    (data / small_foot_file.name).write_bytes(small_foot_file.read_bytes())
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret_8x8x8_uint8.raw").write_bytes(bytes(512))
    (data / "escape_8x8x8_uint8.raw").symlink_to(outside / "secret_8x8x8_uint8.raw")
    return {"data": data, "runs": tmp_path / "runs", "out": tmp_path / "out",
            "outside": outside, "foot": data / small_foot_file.name}  # fmt: skip


@pytest.fixture(scope="session")
def fake_model():
    """An OpenAI-compatible model server that prefers brighter pictures, with a little latency
    so that a generation takes a moment (a run is visibly in progress while tools answer)."""
    from intuitf.testing.fake_mllm import FakeMLLMServer

    with FakeMLLMServer(score=lambda img: float(np.asarray(img, np.float64).mean()),
                        latency=0.02, seed=3) as srv:  # fmt: skip
        yield srv
