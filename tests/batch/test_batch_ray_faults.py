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


def _kill_tree_with(marker: str) -> None:
    """End the processes whose command line holds ``marker`` (and only those)."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit() and int(d.name) != os.getpid():
            try:
                if marker in (d / "cmdline").read_bytes().decode(errors="replace"):
                    pids.append(int(d.name))
            except OSError:
                continue
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for p in pids:
            try:
                os.kill(p, sig)
            except OSError:
                pass
        time.sleep(1.0)


@pytest.fixture
def ray_head(tmp_path_factory):
    """A head started the documented way (``ray start --head --port N``), ended afterwards."""
    pytest.importorskip("ray")
    import socket
    import tempfile

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    temp = tempfile.mkdtemp(prefix="rh", dir="/tmp")  # Ray wants a short path
    started = subprocess.run(
        ["ray", "start", "--head", "--port", str(port), "--num-cpus", "1",
         "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={temp}"],
        capture_output=True, text=True, timeout=180,
    )  # fmt: skip
    try:
        assert started.returncode == 0, started.stdout + started.stderr
        yield port
    finally:
        _kill_tree_with(temp)


def test_joining_a_head_started_with_ray_start_by_its_address(batch_inputs, ray_head, tmp_path):
    vol = str(next(batch_inputs["vols"].glob("*32*.npy")))
    base = [sys.executable, "-m", "intuitf", "batch", str(batch_inputs["picture"]), vol,
            "--max-dim", "32", "--population", "6", "--generations", "1", "--size", "32",
            "--output-size", "48", "--top", "1"]  # fmt: skip
    joined = subprocess.run([*base, "-o", str(tmp_path / "a"), "--ray", f"127.0.0.1:{ray_head}"],
                            capture_output=True, text=True, timeout=300)  # fmt: skip
    assert joined.returncode == 0, joined.stdout + joined.stderr
    assert json.loads((tmp_path / "a" / "summary.json").read_text())["backend"] == "ray"

    # A wrong token is reported as a refusal, at once, not as a hang or "cannot connect".
    env = dict(os.environ, RAY_AUTH_MODE="token", RAY_AUTH_TOKEN="0" * 32)
    t0 = time.monotonic()
    refused = subprocess.run([*base, "-o", str(tmp_path / "b"), "--ray", f"127.0.0.1:{ray_head}"],
                             capture_output=True, text=True, timeout=120, env=env)  # fmt: skip
    out = " ".join((refused.stdout + refused.stderr).split())
    assert refused.returncode == 2, out
    assert "refused this process's authentication token" in out and "RAY_AUTH_TOKEN" in out
    assert time.monotonic() - t0 < 25  # well before the 30 s --ray-timeout
