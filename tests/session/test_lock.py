"""One run folder, one process (issue 8, item 2): a second process is refused at once and told
which process holds the folder; a lock left by a killed process is taken over, with a note."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from intuitf.errors import SessionError
from intuitf.session.lock import RunLock

HOLD = """
import sys, time
from intuitf.session.lock import RunLock
lock = RunLock(sys.argv[1]).acquire()
print("locked", flush=True)
time.sleep(120)
"""


def _holder(root: Path, *extra: str) -> subprocess.Popen:
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(root), *extra],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_process_is_refused_at_once_and_told_who_holds_the_folder(tmp_path):
    proc = _holder(tmp_path / "run", "--base-url", "http://u:SECRET@h/v1")
    try:
        t0 = time.perf_counter()
        with pytest.raises(SessionError) as exc:
            RunLock(tmp_path / "run").acquire()
        assert time.perf_counter() - t0 < 2
        msg = str(exc.value)
        assert f"process {proc.pid}" in msg and "--base-url http://u:***@h/v1" in msg
        assert "SECRET" not in msg and "--resume" in msg
    finally:
        proc.kill()
        proc.wait()


def test_a_lock_left_by_a_killed_process_is_taken_over(tmp_path, caplog):
    root = tmp_path / "run"
    proc = _holder(root)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert json.loads((root / ".lock").read_text())["pid"] == proc.pid  # its record is left
    lock = RunLock(root).acquire()
    try:
        assert lock.took_over["pid"] == proc.pid
        assert f"from process {proc.pid}" in lock.takeover_message
        assert "ended without releasing it" in lock.takeover_message
        assert lock.holder()["pid"] == os.getpid()
    finally:
        lock.release()
    # Released on purpose: the next one takes it quietly.
    again = RunLock(root).acquire()
    assert again.took_over is None and again.takeover_message is None
    again.release()


def test_one_process_cannot_drive_a_folder_twice_either(tmp_path):
    with RunLock(tmp_path) as first:
        assert first.held
        first.acquire()  # re-acquiring one's own lock is a no-op
        with pytest.raises(SessionError, match=f"process {os.getpid()}"):
            RunLock(tmp_path).acquire()
    assert not first.held
    with RunLock(tmp_path):
        pass


@pytest.mark.slow
def test_two_optimize_processes_on_one_run_folder(tmp_path):
    """The CLI end to end: a resume while the run is going is refused within seconds."""
    import numpy as np

    from intuitf.testing.fake_mllm import FakeMLLMServer

    target = np.full((64, 64, 3), 200, np.uint8)
    run = tmp_path / "run"
    args = ["--population", "8", "--generations", "3", "--size", "48", "--output-size", "48",
            "--top", "1", "--text", "red bone"]  # fmt: skip
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    with FakeMLLMServer(target=target, latency=0.3) as srv:
        first = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "intuitf",
                "optimize",
                "phantom",
                *args,
                "--evaluator",
                srv.base_url,
                "-o",
                str(run),
            ],  # fmt: skip
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        try:
            deadline = time.time() + 120
            while time.time() < deadline and srv.stats.requests == 0:
                time.sleep(0.05)
            assert srv.stats.requests > 0, first.communicate(timeout=5)
            t0 = time.perf_counter()
            second = subprocess.run(
                [sys.executable, "-m", "intuitf", "optimize", "--resume", str(run)],
                capture_output=True,
                text=True,
                timeout=60,
                env=env,
            )
            took = time.perf_counter() - t0
            assert first.poll() is None, "the first run ended before the test could race it"
        finally:
            first.kill()
            first.wait()
    out = " ".join((second.stdout + second.stderr).split())  # rich wraps long lines
    assert second.returncode != 0 and "Traceback" not in out
    assert f"process {first.pid}" in out and "in use" in out
    assert took < 20  # the time to start Python and import intuitf; nothing is waited for
