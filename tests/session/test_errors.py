"""Typed run errors: a locked folder, storage trouble and misuse are told apart by their type
(all still :class:`SessionError`, so older ``except SessionError`` code keeps working)."""

from __future__ import annotations

import pytest

from intuitf.errors import RunLocked, SessionError, StorageError
from intuitf.session import RunDirectory, RunSpec, Session
from intuitf.session.lock import RunLock, in_use

SMALL = {"population": 4, "generations": 1, "image_size": 32, "output_size": 32, "top_k": 1}


def test_a_run_folder_in_use_raises_run_locked(tmp_path):
    spec = RunSpec.model_validate({"volume": {"source": "phantom"}, "settings": SMALL})
    with Session.open(spec, tmp_path / "run"):
        assert in_use(tmp_path / "run")
        with pytest.raises(RunLocked, match="in use") as got:
            RunLock(tmp_path / "run").acquire()
        assert isinstance(got.value, SessionError)
    assert not in_use(tmp_path / "run")


def test_storage_trouble_raises_storage_error(tmp_path):
    with pytest.raises(StorageError, match="not a run folder"):
        RunDirectory(tmp_path).read_run()
    (tmp_path / "run.json").write_text("{ cut short")
    with pytest.raises(StorageError, match="corrupt"):
        RunDirectory(tmp_path).read_run()
    with pytest.raises(StorageError):
        Session.resume(tmp_path / "missing")
