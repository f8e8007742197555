"""Helpers of the web backend's tests: a small app, a real uvicorn on loopback, run waiting."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path

TOKEN = "test-token-0123456789abcdef"
AUTH = {"Authorization": f"token {TOKEN}"}
#: Small and fast: the offline metric judge, 6 candidates, 2 generations, 48-pixel pictures.
SMALL = {"population": 6, "generations": 2, "image_size": 48, "output_size": 64, "top_k": 2}


def make_app(runs: Path, **kw):
    from intuitf.web.app import create_app

    kw.setdefault("token", TOKEN)
    kw.setdefault("allowed_hosts", ["testserver", "127.0.0.1", "localhost"])
    kw.setdefault("default_settings", SMALL)
    kw.setdefault("sse_keepalive", 1.0)
    return create_app(runs, **kw)


def wait_run(client, name: str, timeout: float = 120.0, headers=AUTH) -> dict:
    """Poll a run until it is no longer going; its detail."""
    deadline = time.monotonic() + timeout
    while True:
        d = client.get(f"/api/runs/{name}", headers=headers).json()
        if d["info"]["status"] != "running":
            return d
        if time.monotonic() > deadline:
            raise AssertionError(f"run {name} still going after {timeout} s: {d}")
        time.sleep(0.2)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LiveServer:
    """uvicorn serving ``app`` on a free loopback port, in a thread."""

    def __init__(self, app) -> None:
        import uvicorn

        self.port = free_port()
        self.app = app
        config = uvicorn.Config(
            app, host="127.0.0.1", port=self.port, log_level="warning", ws="auto"
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def ws_url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    def __enter__(self) -> LiveServer:
        self.thread.start()
        deadline = time.monotonic() + 30
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        return self

    def __exit__(self, *exc) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=60)
