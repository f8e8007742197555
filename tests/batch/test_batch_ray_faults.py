"""Ray, as a user meets it: a killed batch driver takes its workers' requests and its local Ray
instance with it; a resume runs on Ray again and says so. Slow (Ray starts in each)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from intuitf.imageio import load_image
from intuitf.testing.fake_mllm import FakeMLLMServer

pytestmark = pytest.mark.slow


def _ray_processes(driver_pid: int) -> list[int]:
    """Ray's own processes of the session the driver ``driver_pid`` started."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            cmd = (d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if (
            f"_{driver_pid} " in cmd + " "
            and "session_dir=" in cmd
            or (f"_{driver_pid}/" in cmd and "/tmp/ray/session_" in cmd)
        ):
            out.append(int(d.name))
    return out


def _alive(pids: list[int]) -> list[int]:
    out = []
    for p in pids:
        try:
            state = Path(f"/proc/{p}/stat").read_text().split()[2]
        except OSError:
            continue
        if state != "Z":
            out.append(p)
    return out


def _cmd(batch_inputs, root, url, *extra) -> list[str]:
    return [sys.executable, "-m", "intuitf", "batch", str(batch_inputs["picture"]),
            str(batch_inputs["vols"]), "--evaluator", url, "--max-dim", "32", "--population",
            "8", "--generations", "4", "--size", "32", "--output-size", "48", "--top", "1",
            "--workers", "2", "--per-worker", "2", "-o", str(root), *extra]  # fmt: skip


def test_a_killed_driver_stops_its_workers_and_its_local_ray(batch_inputs, tmp_path):
    pytest.importorskip("ray")
    target = load_image(batch_inputs["picture"])
    with FakeMLLMServer(target=target, latency=0.3) as srv:
        root = tmp_path / "out"
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        proc = subprocess.Popen(_cmd(batch_inputs, root, srv.base_url, "--ray"),
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)  # fmt: skip
        deadline = time.time() + 240
        while time.time() < deadline and srv.stats.requests < 12 and proc.poll() is None:
            time.sleep(0.05)
        assert srv.stats.requests >= 12, "the batch never got going"
        ray_pids = _ray_processes(proc.pid)
        assert ray_pids, "no Ray processes found for this batch"
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
        at_kill, in_flight = srv.stats.requests, srv.stats.in_flight
        time.sleep(8.0)  # Ray alone would let the workers go on for seconds
        grew = srv.stats.requests - at_kill
    assert grew <= in_flight, f"{grew} requests after the kill, {in_flight} were in flight"
    deadline = time.time() + 30
    while _alive(ray_pids) and time.time() < deadline:
        time.sleep(0.5)
    assert not _alive(ray_pids), "the local Ray instance outlived the batch that started it"


def test_a_resume_runs_on_ray_again_and_says_so(batch_inputs, tmp_path):
    pytest.importorskip("ray")
    target = load_image(batch_inputs["picture"])
    vol = str(next(batch_inputs["vols"].glob("*32*.npy")))
    with FakeMLLMServer(target=target, latency=0.0) as srv:
        root = tmp_path / "out"
        cmd = _cmd(batch_inputs, root, srv.base_url, "--ray")
        cmd[cmd.index(str(batch_inputs["vols"]))] = vol
        cmd[cmd.index("--generations") + 1] = "1"
        first = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        assert first.returncode == 0, first.stdout + first.stderr
        assert json.loads((root / "batch.json").read_text())["backend"] == {"ray": "local"}
        again = subprocess.run([sys.executable, "-m", "intuitf", "batch", "--resume", str(root)],
                               capture_output=True, text=True, timeout=300)  # fmt: skip
    out = " ".join(again.stdout.split())
    assert again.returncode == 0, again.stdout + again.stderr
    assert "on Ray (local) as the batch was started" in out
    assert json.loads((root / "summary.json").read_text())["backend"] == "ray"
