"""The atomic writer gives files the mode any new file gets: others can read what intuitf writes."""

from __future__ import annotations

import os
import stat

import pytest

from intuitf.fileio import atomic_write_bytes, atomic_write_text


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    try:
        yield
    finally:
        os.umask(old)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_new_files_follow_the_umask(tmp_path, umask_022):
    out = atomic_write_bytes(tmp_path / "best.png", b"x")
    assert _mode(out) == 0o644  # readable by group and others, like open(..., "w")
    plain = tmp_path / "plain.txt"
    plain.write_text("y")
    assert _mode(out) == _mode(plain)


def test_a_stricter_umask_is_honoured(tmp_path):
    old = os.umask(0o077)
    try:
        out = atomic_write_text(tmp_path / "summary.json", "{}")
    finally:
        os.umask(old)
    assert _mode(out) == 0o600


def test_an_existing_file_keeps_its_mode(tmp_path, umask_022):
    target = tmp_path / "run.json"
    target.write_text("old")
    os.chmod(target, 0o640)
    atomic_write_text(target, "new")
    assert target.read_text() == "new"
    assert _mode(target) == 0o640
    assert [p.name for p in tmp_path.iterdir()] == ["run.json"]  # no temporary file left
