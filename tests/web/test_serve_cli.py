"""``intuitf serve`` as a person starts it (issue #20): a taken port said plainly, a token kept
across restarts (or given), ``--spacing`` for the volumes it offers."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def _serve(root: Path, *args: str, wait: float = 90.0) -> tuple[subprocess.Popen, str, list[str]]:
    """Start serve; (process, printed address or '', output lines so far)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "240", "NO_COLOR": "1"}
    env.pop("INTUITF_DATA", None)
    env.pop("INTUITF_TOKEN", None)
    cmd = [sys.executable, "-m", "intuitf", "serve", "--no-browser", "--runs", str(root / "runs"),
           *args]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env, cwd=root)  # fmt: skip
    lines: list[str] = []
    deadline = time.monotonic() + wait
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line.rstrip())
        m = re.search(r"(http://127\.0\.0\.1:\d+/\?token=[\w-]+)", line)
        if m:
            return proc, m.group(1), lines
    return proc, "", lines


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()


def test_a_taken_port_is_said_plainly(tmp_path):
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        proc, url, lines = _serve(tmp_path, "--port", str(port))
        try:
            out = "\n".join(lines) + (proc.stdout.read() if proc.stdout else "")
            proc.wait(timeout=60)
        finally:
            _stop(proc)
    assert not url, "the address was printed although the port is taken"
    assert proc.returncode != 0
    assert f"Port {port} is taken" in out, out
    assert "Errno" not in out and "Traceback" not in out, out


def test_token_is_kept_across_restarts_or_given(tmp_path):
    tokens = []
    for _ in range(2):
        proc, url, lines = _serve(tmp_path)
        _stop(proc)
        assert url, lines
        tokens.append(url.split("token=")[1])
    assert tokens[0] == tokens[1]
    kept = tmp_path / "runs" / ".token"
    assert kept.read_text().strip() == tokens[0]
    assert oct(kept.stat().st_mode & 0o777) == "0o600"
    given = "a-token-given-on-the-command-line"
    proc, url, lines = _serve(tmp_path, "--token", given)
    _stop(proc)
    assert url.endswith(f"token={given}"), lines


def test_spacing_is_given_to_the_volumes_served(tmp_path):
    import httpx

    data = tmp_path / "data"
    data.mkdir()
    np.arange(8 * 8 * 8, dtype=np.uint8).tofile(data / "cube_8x8x8_uint8.raw")
    proc, url, lines = _serve(tmp_path, "--data", str(data), "--spacing", "1,1,2.5")
    try:
        assert url, lines
        base, token = url.split("/?token=")
        auth = {"Authorization": f"token {token}"}
        deadline = time.monotonic() + 60
        while True:  # the address is printed before the server listens
            try:
                httpx.get(base + "/api/info", headers=auth)
                break
            except httpx.ConnectError:
                assert time.monotonic() < deadline, lines
                time.sleep(0.2)
        vols = {v["id"]: v for v in httpx.get(base + "/api/volumes", headers=auth).json()}
        cube = next(v for v in vols.values() if v["source"] == "data")
        assert cube["spacing"] == [1.0, 1.0, 2.5]
        assert vols["phantom"]["spacing"] is None
        # The page may set a raw volume's spacing too.
        r = httpx.patch(f"{base}/api/volumes/{cube['id']}", headers=auth,
                        json={"spacing": [2, 2, 2]})  # fmt: skip
        assert r.status_code == 200 and r.json()["spacing"] == [2.0, 2.0, 2.0]
        r = httpx.patch(f"{base}/api/volumes/{cube['id']}", headers=auth,
                        json={"spacing": [0, 1, 1]})  # fmt: skip
        assert r.status_code == 422 and r.json()["detail"]
    finally:
        _stop(proc)
