"""The event stream and the view socket against a real uvicorn on loopback.

SSE: a subscriber that connects late, or reconnects with Last-Event-ID, replays exactly the
events it missed, in order. WebSocket: one frame in flight; requests sent while it renders
replace each other, so of five sent at once the server renders the first and the last.
"""

from __future__ import annotations

import io
import json
import time

import httpx
import numpy as np
import pytest
from PIL import Image

from helpers.web_backend import AUTH, TOKEN, LiveServer, make_app, wait_run


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    app = make_app(tmp_path_factory.mktemp("runs"))
    with LiveServer(app) as srv:
        yield srv


@pytest.fixture(scope="module")
def http(server):
    with httpx.Client(base_url=server.url, headers=AUTH, timeout=60) as c:
        yield c


def read_sse(http, path: str, until: str = "run_ended", headers=None, timeout: float = 120.0):
    """Events of an SSE stream up to the first of type ``until``: [(id, type, data)]."""
    out = []
    deadline = time.monotonic() + timeout
    with http.stream("GET", path, headers=headers or {}) as r:
        assert r.status_code == 200
        assert r.headers["content-type"].startswith("text/event-stream")
        ev: dict = {}
        for line in r.iter_lines():
            if time.monotonic() > deadline:
                raise AssertionError(f"no {until} within {timeout} s; got {out[-3:]}")
            if line.startswith(":") or line.startswith("retry:"):
                continue
            if not line:
                if ev:
                    out.append((int(ev["id"]), ev["event"], json.loads(ev["data"])))
                    if ev["event"] == until:
                        return out
                ev = {}
                continue
            key, _, value = line.partition(": ")
            ev[key] = value
    raise AssertionError("stream ended")


@pytest.fixture(scope="module")
def finished(http) -> str:
    r = http.post("/api/runs", json={"volume": "phantom", "name": "sse"})
    assert r.status_code == 201, r.text
    name = r.json()["name"]
    wait_run(http, name)
    return name


def test_live_subscriber_sees_every_event_in_order(http):
    r = http.post("/api/runs", json={"volume": "phantom", "name": "live"})
    name = r.json()["name"]
    events = read_sse(http, f"/api/runs/{name}/events")
    seqs = [e[0] for e in events]
    assert seqs == list(range(1, len(seqs) + 1))
    types = [e[1] for e in events]
    assert types[0] == "stage_started" and types[-1] == "run_ended"
    assert types.count("generation_ended") == 2 and "match_judged" in types
    for seq, typ, data in events:
        assert data["seq"] == seq and data["type"] == typ and data["run"] == name
    ended = next(d for _, t, d in events if t == "generation_ended")
    assert ended["data"]["ranking"] and ended["data"]["generation"] == 0


def test_late_subscriber_replays_from_since_and_last_event_id(http, finished):
    full = read_sse(http, f"/api/runs/{finished}/events")
    assert full[0][0] == 1
    late = read_sse(http, f"/api/runs/{finished}/events?since=3")
    assert [e[0] for e in late] == [e[0] for e in full[3:]]
    assert late[0][2] == full[3][2]
    again = read_sse(http, f"/api/runs/{finished}/events", headers={"Last-Event-ID": "5"})
    assert [e[0] for e in again] == [e[0] for e in full[5:]]


def test_stream_follows_a_run_continued_later(http):
    r = http.post("/api/runs", json={"volume": "phantom", "settings": {"generations": 3}})
    name = r.json()["name"]
    assert http.post(f"/api/runs/{name}/cancel").status_code == 200
    first = read_sse(http, f"/api/runs/{name}/events")
    assert first[-1][2]["data"]["reason"] == "cancelled"
    wait_run(http, name)
    last = first[-1][0]
    assert http.post(f"/api/runs/{name}/continue").status_code == 200
    more = read_sse(http, f"/api/runs/{name}/events?since={last}")
    assert more[0][0] == last + 1 and more[0][1] == "run_started"
    assert [e[0] for e in more] == list(range(last + 1, last + 1 + len(more)))
    assert more[-1][2]["data"]["reason"] == "completed"


def _tf(http, qid=None):
    if qid is None:
        from intuitf.tf.defaults import default_tf
        from intuitf.volume.phantom import phantom

        v = phantom()
        return default_tf(v.histogram()[0], v.value_range).to_dict()
    return http.get(f"/api/candidates/{qid}").json()["tf"]


def _connect(server, **kw):
    from websockets.sync.client import connect

    return connect(f"{server.ws_url}/api/view?token={TOKEN}", open_timeout=30, **kw)


def _frames(ws, last: int, quiet: float = 1.0, timeout: float = 120.0):
    """Header/binary pairs (and errors) until the answer to request ``last`` and then
    ``quiet`` seconds of silence (anything else that comes is collected too)."""
    out = []
    deadline = time.monotonic() + timeout
    seen_last = False
    while True:
        wait = quiet if seen_last else max(0.1, deadline - time.monotonic())
        try:
            msg = ws.recv(timeout=wait)
        except TimeoutError:
            if seen_last:
                return out
            raise AssertionError(f"no answer to request {last} within {timeout} s: {out}") from None
        assert isinstance(msg, str), "a binary message without its header"
        head = json.loads(msg)
        seen_last = seen_last or head.get("req") == last
        if "error" in head:
            out.append((head, None))
            continue
        data = ws.recv(timeout=30)
        assert isinstance(data, bytes), "the header must be followed by the picture"
        out.append((head, data))


def test_newest_camera_wins(server):
    tf = _tf(None)
    with _connect(server) as ws:
        base = {"target": {"volume": "phantom", "tf": tf}, "size": 256, "shaded": True,
                "background": [0, 0, 0], "quality": "full"}  # fmt: skip
        for i in range(1, 6):
            ws.send(json.dumps({**base, "req": i, "camera": {"azimuth": 10 * i, "elevation": 5}}))
        frames = _frames(ws, last=5)
    assert [h["req"] for h, _ in frames] == [1, 5]
    for head, data in frames:
        assert head["format"] == "png" and head["quality"] == "full"
        assert head["width"] == head["height"] == 256 and head["ms"] > 0
        img = np.asarray(Image.open(io.BytesIO(data)))
        assert img.shape == (256, 256, 3) and img.any()


def test_drag_frames_are_small_jpegs_and_errors_come_back(server, http, finished):
    qid = http.get(f"/api/runs/{finished}").json()["gallery"][0]["qid"]
    with _connect(server) as ws:
        req = {"req": 7, "target": {"candidate": qid}, "camera": {"azimuth": 40},
               "size": 256, "shaded": False, "quality": "drag"}  # fmt: skip
        ws.send(json.dumps(req))
        (head, data), *_ = _frames(ws, last=7)
        assert head == {**head, "req": 7, "format": "jpeg", "width": 128, "height": 128}
        assert data[:2] == b"\xff\xd8"
        ws.send(json.dumps({**req, "req": 8, "quality": "full", "highlight": [0, 1]}))
        (head, data), *_ = _frames(ws, last=8)
        assert head["req"] == 8 and head["format"] == "png" and head["width"] == 256
        ws.send(json.dumps({**req, "req": 9, "target": {"candidate": "../../etc/g000-000"}}))
        ws.send(json.dumps({**req, "req": 10, "target": {"volume": "/etc/passwd", "tf": {}}}))
        ws.send(json.dumps({**req, "req": 11, "camera": {"zoom": -1}}))
        ws.send("not json")
        got = _frames(ws, last=11)
    errors = [h for h, d in got if d is None]
    # the first request (the socket was idle) and the newest are always answered
    assert {e["req"] for e in errors} >= {9, 11, None}
    assert all(e["error"] for e in errors)
