"""The web app under load: view frames, the first gallery update and event delivery, measured
against a real ``uvicorn`` on a free loopback port while a run renders its generations.

Run: ``python benchmarks/web.py`` (options: ``--volume ID``, ``--data DIR``, ``--population``,
``--image-size``, ``--frames``, ``--stills``). The server runs in its own process (as
``intuitf serve`` does); this process is the client: an SSE reader and a WebSocket client.

Measured, all while the run is going (and again with no run, for comparison):

- drag frames: ``quality: "drag"`` for a 256-pixel view (a 128² JPEG, or 96² / 64² when the
  server's adaptive level of detail finds the machine too slow for its 40 ms budget; the sides
  are printed; ``--no-lod`` keeps 128²), the next request sent as soon as a frame arrives (one
  in flight, as the page does): request → picture, median / p90;
- full stills: 256² shaded PNG, request → picture;
- first gallery update: from ``POST /api/runs`` to the first ``generation_ended`` event;
- event delivery: the event's own time (set when the run emitted it) to its receipt here.

The "server" column is the frame header's ``ms``: the server's own time from the parsed request
to the encoded picture, without the socket; "wait" of it waiting for the render worker (behind
a tournament render), "render" the render itself (medians).

Targets on the 2-core reference machine: drag median < 50 ms, full still < 150 ms, events
< 200 ms, all while a run is going.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time

import httpx


def serve(port: int, runs: str, token: str, data: str | None, budget: float | None) -> None:
    """The server process: ``intuitf serve`` without a browser, on ``port``."""
    from intuitf.web.app import create_app, make_server

    app = create_app(runs, [], data or None, token=token, drag_budget_ms=budget,
                     allowed_hosts=[f"127.0.0.1:{port}", f"localhost:{port}"])  # fmt: skip
    make_server(app, "127.0.0.1", port).run()


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def pct(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    v = sorted(values)
    k = (len(v) - 1) * q
    lo, hi = int(k), min(int(k) + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (k - lo)


class EventReader(threading.Thread):
    """Reads a run's SSE stream; keeps (event, receipt time)."""

    def __init__(self, base: str, headers: dict, run: str) -> None:
        super().__init__(daemon=True)
        self.base, self.headers, self.run_name = base, headers, run
        self.events: list[tuple[dict, float]] = []
        self.first_gallery: float | None = None
        self.stop = False

    def run(self) -> None:
        with httpx.Client(base_url=self.base, headers=self.headers, timeout=None) as c:
            with c.stream("GET", f"/api/runs/{self.run_name}/events?since=0") as r:
                data = None
                for line in r.iter_lines():
                    if self.stop:
                        return
                    if line.startswith("data: "):
                        data = line[6:]
                    elif not line and data:
                        now = time.time()
                        e = json.loads(data)
                        self.events.append((e, now))
                        if e["type"] == "generation_ended" and self.first_gallery is None:
                            self.first_gallery = now
                        if e["type"] == "run_ended":
                            return
                        data = None


#: The sides of the frames each measurement got (drag frames adapt theirs to the machine).
SIDES: dict[str, list[list[int]]] = {}


def frames(ws_url: str, target: dict, quality: str, n: int, shaded: bool = True):
    """Round-trip times (ms) of ``n`` requests, each sent when the previous frame arrived,
    and the server's own times (the headers' ``ms``)."""
    server_ms: list[float] = []
    waits: list[float] = []
    renders: list[float] = []
    sides: list[int] = []
    from websockets.sync.client import connect

    out = []
    with connect(ws_url, open_timeout=30, max_size=None) as ws:
        for i in range(n + 1):
            req = {"req": i, "target": target, "size": 256, "shaded": shaded,
                   "background": [0, 0, 0], "quality": quality,
                   "camera": {"azimuth": (7 * i) % 360, "elevation": 10 + (i % 5)}}  # fmt: skip
            t = time.perf_counter()
            ws.send(json.dumps(req))
            head = json.loads(ws.recv(timeout=60))
            if "error" in head:
                raise RuntimeError(head)
            ws.recv(timeout=60)
            if i:  # the first frame warms the socket and the target up
                out.append((time.perf_counter() - t) * 1000.0)
                server_ms.append(float(head["ms"]))
                waits.append(float(head.get("wait_ms", 0.0)))
                renders.append(float(head.get("render_ms", 0.0)))
                sides.append(int(head["width"]))
    SIDES[quality] = SIDES.get(quality, []) + [sides]
    return out, server_ms, waits, renders


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--volume", default="phantom", help="volume id (default: phantom)")
    ap.add_argument("--data", default=None, help="folder of volumes to offer")
    ap.add_argument("--population", type=int, default=16)
    ap.add_argument("--image-size", type=int, default=128)
    ap.add_argument("--generations", type=int, default=60)
    ap.add_argument("--frames", type=int, default=40, help="drag frames per measurement")
    ap.add_argument("--stills", type=int, default=12, help="full stills per measurement")
    ap.add_argument(
        "--no-lod",
        action="store_true",
        help="drag frames always 128² (no adaptive level of detail)",
    )
    ap.add_argument("--serve", nargs=5, metavar=("PORT", "RUNS", "TOKEN", "DATA", "BUDGET"),
                    help=argparse.SUPPRESS)  # fmt: skip
    args = ap.parse_args()
    if args.serve:
        port, runs, token, data, budget = args.serve
        serve(int(port), runs, token, None if data == "-" else data,
              None if budget == "-" else float(budget))  # fmt: skip
        return

    load_before = os.getloadavg()[0]
    port, token = free_port(), "bench-token"
    runs = tempfile.mkdtemp(prefix="intuitf-web-bench-")
    server = subprocess.Popen(
        [
            sys.executable,
            __file__,
            "--serve",
            str(port),
            runs,
            token,
            args.data or "-",
            "-" if args.no_lod else "40",
        ],
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    base = f"http://127.0.0.1:{port}"
    ws_url = f"ws://127.0.0.1:{port}/api/view?token={token}"
    headers = {"Authorization": f"token {token}"}
    try:
        with httpx.Client(base_url=base, headers=headers, timeout=120) as c:
            deadline = time.monotonic() + 60
            while True:
                try:
                    if c.get("/api/info").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if time.monotonic() > deadline or server.poll() is not None:
                    raise SystemExit("the server did not start")
                time.sleep(0.1)
            # A warm-up: volume loaded, kernels compiled, before anything is timed.
            from intuitf.tf.defaults import default_tf

            hist = c.get(f"/api/volumes/{args.volume}/histogram").json()
            import numpy as np

            counts = np.exp(np.asarray(hist["counts"]) * 10.0)
            tf = default_tf(counts, tuple(hist["value_range"])).to_dict()
            target = {"volume": args.volume, "tf": tf}
            frames(ws_url, target, "drag", 3)
            frames(ws_url, target, "full", 3)

            settings = {"population": args.population, "image_size": args.image_size,
                        "generations": args.generations}  # fmt: skip
            t_post = time.time()
            r = c.post("/api/runs", json={"volume": args.volume, "settings": settings,
                                          "intent": "opaque white bone, faint red skin"})  # fmt: skip
            r.raise_for_status()
            name = r.json()["name"]
            reader = EventReader(base, headers, name)
            reader.start()
            while reader.first_gallery is None:
                if time.time() - t_post > 300:
                    raise SystemExit("no generation ended within 5 minutes")
                time.sleep(0.01)
            first_gallery = reader.first_gallery - t_post
            # The run's best so far: the same TF is measured with the run going and without.
            qid = c.get(f"/api/runs/{name}").json()["gallery"][0]["qid"]
            view = {"candidate": qid}
            busy_drag = frames(ws_url, view, "drag", args.frames)
            busy_full = frames(ws_url, view, "full", args.stills)
            detail = c.get(f"/api/runs/{name}").json()
            gens_during = detail["progress"]["generation"] - 1
            still_running = detail["info"]["status"] == "running"
            c.post(f"/api/runs/{name}/cancel")
            reader.join(timeout=60)
            while c.get(f"/api/runs/{name}").json()["info"]["status"] == "running":
                time.sleep(0.1)
            idle_drag = frames(ws_url, view, "drag", args.frames)
            idle_full = frames(ws_url, view, "full", args.stills)
            delays = [(now - e["time"]) * 1000.0 for e, now in reader.events
                      if e["time"] >= t_post]  # fmt: skip
    finally:
        server.terminate()
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()

    def row(what, values, target_ms):
        extra = ""
        if isinstance(values, tuple):
            values, server_ms, waits, renders = values
            extra = "".join(f"{statistics.median(v):>9.1f}" for v in (server_ms, waits, renders))
        med, p90 = statistics.median(values), pct(values, 0.9)
        ok = "" if target_ms is None else ("yes" if med < target_ms else "NO")
        t = "" if target_ms is None else f"< {target_ms:.0f}"
        print(f"{what:<44}{len(values):>4}{med:>8.1f}{p90:>8.1f}{max(values):>8.1f}"
              f"{t:>7}{ok:>5}{extra}")  # fmt: skip

    print()
    print(f"volume {args.volume}; run: population {args.population}, image {args.image_size}², "
          f"metric judge; {os.cpu_count()} cores; load average at the end "
          f"{os.getloadavg()[0]:.1f} (before the start {load_before:.1f})")  # fmt: skip
    print(f"{'measure (ms)':<44}{'n':>4}{'median':>8}{'p90':>8}{'max':>8}{'target':>7}"
          f"{'met':>5}{'server':>9}{'wait':>9}{'render':>9}")  # fmt: skip
    row("drag frame JPEG, run going", busy_drag, 50)
    row("full still 256² shaded PNG, run going", busy_full, 150)
    row("drag frame JPEG, same TF, no run", idle_drag, None)
    row("full still 256² shaded PNG, same TF, no run", idle_full, None)
    row("event delivery (event time -> receipt)", delays, 200)
    print(f"{'first gallery update (POST -> gen 0 ended)':<44}{1:>4}"
          f"{first_gallery * 1000:>8.0f}")  # fmt: skip
    for label, runs_ in (("run going", SIDES["drag"][1]), ("no run", SIDES["drag"][2])):
        counts = {side: runs_.count(side) for side in sorted(set(runs_), reverse=True)}
        print(f"drag frame sides, {label}: " + ", ".join(f"{k}²×{v}" for k, v in counts.items()))
    print(f"view: the run's best candidate after its first generation ({qid}); generations the "
          f"run finished while frames were measured: {gens_during}; still going at the end: "
          f"{still_running}")  # fmt: skip


if __name__ == "__main__":
    main()
