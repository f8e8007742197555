"""Helpers of the browser tests: start and stop ``intuitf serve``, find Chromium."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
]
#: Small and fast runs: what the tests type into the query panel.
SMALL = {"population": "6", "generations": "2", "image_size": "64"}


def skip_reason() -> str | None:
    if CHROMIUM is None:
        return "no chromium binary on PATH (scripts/test.sh installs Debian's chromium as root)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the playwright package is missing (pip install -e '.[test]')"
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class WebServer:
    """A running ``intuitf serve``: its address, token and runs folder, and a small API client."""

    url: str  # the printed address, with ?token=
    base: str
    token: str
    runs: Path
    proc: subprocess.Popen
    log: list[str] = field(default_factory=list)

    def api(self, method: str, path: str, body=None, timeout: float = 60.0):
        """JSON from the server's API (with the token), for setting up and checking."""
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data, method=method)
        req.add_header("Authorization", f"token {self.token}")
        if data is not None:
            req.add_header("Content-Type", "application/json")
        with urllib.request.urlopen(req, timeout=timeout) as resp:
            raw = resp.read()
            return (
                json.loads(raw) if raw and "json" in resp.headers.get("Content-Type", "") else raw
            )

    def wait_run(self, name: str, timeout: float = 180.0) -> dict:
        """The run's detail once it is no longer running."""
        deadline = time.monotonic() + timeout
        while True:
            d = self.api("GET", f"/api/runs/{name}")
            snap = d.get("snapshot") or {}
            if d["info"]["status"] != "running" and snap.get("status") in (None, "ended", "idle"):
                return d
            if time.monotonic() > deadline:
                raise AssertionError(f"run {name} still going after {timeout} s: {d['info']}")
            time.sleep(0.3)

    def start_run(self, text: str, judge: str = "metric", **settings) -> str:
        """A run started through the API (for tests about something else than starting)."""
        spec = {
            "volume": "phantom",
            "intent": {"kind": "text", "text": text},
            "judge": {"spec": judge},
            "settings": {"population": 6, "generations": 2, "image_size": 64, **settings},
        }
        return self.api("POST", "/api/runs", spec)["name"]


def start_server(root: Path) -> WebServer:
    """``intuitf serve`` on a free port with its runs (and an empty --data) under ``root``."""
    runs = root / "runs"
    data = root / "data"  # an empty --data folder: only the built-in phantom is offered
    data.mkdir()
    port = _free_port()
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "240", "NO_COLOR": "1"}
    env.pop("INTUITF_DATA", None)
    cmd = [
        sys.executable, "-m", "intuitf", "serve", "--no-browser",
        "--port", str(port), "--runs", str(runs), "--data", str(data),
    ]  # fmt: skip
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env, cwd=root
    )
    log: list[str] = []
    found: dict[str, str] = {}
    ready = threading.Event()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            log.append(line.rstrip())
            m = re.search(r"(http://127\.0\.0\.1:\d+/\?token=[\w-]+)", line)
            if m and "url" not in found:
                found["url"] = m.group(1)
                ready.set()
        ready.set()

    threading.Thread(target=read, daemon=True).start()
    ready.wait(90)
    if "url" not in found:
        proc.kill()
        raise RuntimeError("intuitf serve printed no address:\n" + "\n".join(log))
    url = found["url"]
    base = url.split("/?", 1)[0]
    token = url.split("token=", 1)[1]
    server = WebServer(url=url, base=base, token=token, runs=runs, proc=proc, log=log)
    deadline = time.monotonic() + 60
    while True:
        try:
            server.api("GET", "/api/info", timeout=5)
            break
        except (urllib.error.URLError, ConnectionError):
            if time.monotonic() > deadline or proc.poll() is not None:
                proc.kill()
                raise RuntimeError("intuitf serve does not answer:\n" + "\n".join(log)) from None
            time.sleep(0.2)
    return server


def start_server_with(root: Path, volumes: list[str]) -> WebServer:
    """``start_server`` offering ``volumes`` (file names in the real-volume folder) as well,
    those of them that are there."""
    from helpers.data import DATA, data_dir

    server = start_server(root)
    if data_dir() is not None:
        for name in volumes:
            if (DATA / name).exists():
                (root / "data" / name).symlink_to(DATA / name)  # --data is rescanned on each list
    return server


def open_app(
    chromium,
    url: str,
    width: int = 1440,
    height: int = 900,
    *,
    extra_args=(),
    timeout_ms: float | None = None,
):
    """Headless Chromium (with ``extra_args`` beside the usual ones) at the app's ``url``,
    ready: (browser, page). The page's uncaught errors collect in ``page.errors``;
    ``timeout_ms`` is the page's default timeout (Playwright's own when None)."""
    b = chromium.launch(
        executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS + list(extra_args)
    )
    page = b.new_page(viewport={"width": width, "height": height})
    if timeout_ms is not None:
        page.set_default_timeout(timeout_ms)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(url)
    page.wait_for_selector("body.ready")
    page.errors = errors
    return b, page


def stop_server(server: WebServer) -> None:
    """Ctrl-C, as a person would: running runs stop between matches and are kept."""
    proc = server.proc
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=10)


def show_run(page, run: str) -> None:
    """Open the history tab that holds ``run`` and make the run current."""
    page.wait_for_function(
        "run => window.intuitfDebug.state.tree && JSON.stringify(window.intuitfDebug.state.tree)"
        '.includes(`"name":"${run}"`)',
        arg=run,
    )
    tab = page.locator(f"#history-tabs .tab[data-run='{run}']")
    if tab.count():
        tab.click()
    page.click(f".run-node[data-run='{run}'] > .run-head")
    page.wait_for_function(
        "run => { const s = window.intuitfDebug.state;"
        " return (s.current || '').startsWith(run + '/') && s.candidate && s.candidate.qid === s.current; }",
        arg=run,
    )
