"""The web API as a person meets it (issue #20): live verdicts, prompt ends, bad input refused
with a message and nothing written, volume and run housekeeping."""

from __future__ import annotations

import threading
import time

import pytest
from fastapi.testclient import TestClient

from helpers.web_backend import AUTH, make_app, wait_run


@pytest.fixture(scope="module")
def web_app(tmp_path_factory):
    return make_app(tmp_path_factory.mktemp("runs"))


@pytest.fixture(scope="module")
def client(web_app):
    with TestClient(web_app, headers=AUTH) as c:
        yield c


def _live(client, name: str):
    return client.app.state.web.registry.get(name)


def _start(client, **settings) -> str:
    r = client.post(
        "/api/runs",
        json={"volume": "phantom", "intent": {"kind": "text", "text": "white bone"},
              "settings": settings},
    )  # fmt: skip
    assert r.status_code == 201, r.text
    return r.json()["name"]


def _wait(pred, timeout: float = 120.0, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > deadline:
            raise AssertionError(f"no {what} after {timeout} s")
        time.sleep(0.05)


# -- 3: a verdict on a paused run re-ranks at once ----------------------------------------------
def test_verdict_on_a_paused_run_reranks_at_once(client):
    name = _start(client, generations=3)
    live = _live(client, name)
    assert live is not None
    paused = threading.Event()

    def pause_in_second_generation(e) -> None:
        # Paused inside generation 1 (on the run's own thread, as its events are emitted):
        # the gallery shows generation 0 while generation 1 is being judged.
        if e.type == "generation_started" and e.data.get("generation") == 1:
            live.session.pause()
            paused.set()

    live.session.events.subscribe(pause_in_second_generation)
    _wait(paused.is_set, what="second generation")
    d = client.get(f"/api/runs/{name}").json()
    assert d["snapshot"]["status"] == "paused"
    ids = [g["id"] for g in d["gallery"]]
    best, worst = ids[0], ids[-1]
    r = client.post(f"/api/runs/{name}/prefer", json={"better": worst, "worse": best})
    assert r.status_code == 200, r.text
    ranking = r.json()["ranking"]
    assert ranking.index(worst) < ranking.index(best), ranking
    # The page's gallery and ratings show it at once, while the run is still paused.
    d = client.get(f"/api/runs/{name}").json()
    assert d["snapshot"]["status"] == "paused"
    order = [g["id"] for g in d["gallery"]]
    assert order.index(worst) < order.index(best), order
    ratings = d["snapshot"]["ratings"]
    assert ratings[worst] > ratings[best]
    # Undo restores the model's order at once too.
    r = client.post(f"/api/runs/{name}/undo", json={})
    assert r.status_code == 200
    assert [g["id"] for g in client.get(f"/api/runs/{name}").json()["gallery"]] == ids
    # The run goes on and ends as usual.
    client.post(f"/api/runs/{name}/prefer", json={"better": worst, "worse": best})
    assert client.post(f"/api/runs/{name}/proceed").status_code == 200
    d = wait_run(client, name)
    assert d["info"]["status"] == "completed"


# -- 5: a run's end shows at once, even while its outputs are written --------------------------
def test_run_end_shows_while_outputs_are_written(client, monkeypatch):
    from intuitf.session import Session

    release = threading.Event()
    writing = threading.Event()
    real = Session.write_outputs

    def slow_outputs(self, *a, **kw):
        writing.set()
        release.wait(60)
        return real(self, *a, **kw)

    monkeypatch.setattr(Session, "write_outputs", slow_outputs)
    name = _start(client, generations=1)
    try:
        _wait(writing.is_set, what="outputs being written")
        d = client.get(f"/api/runs/{name}").json()
        assert d["info"]["status"] == "completed", d["info"]
        assert d["progress"]["status"] == "completed"
        runs = {r["name"]: r for r in client.get("/api/runs").json()}
        assert runs[name]["status"] == "completed"
        tree = client.get("/api/tree").json()
        node = next(n for n in tree if n["run"]["name"] == name)
        assert node["run"]["status"] == "completed"
    finally:
        release.set()
    wait_run(client, name)


# -- 6: every bad input is a 4xx with a message, and a refused run writes nothing ---------------
BAD_SETTINGS = [
    {"population": "many"},
    {"seed": -1},
    {"stages": [["bogus", 1]]},
    {"stages": "initialize"},
    {"background": [1e9, 0, 0]},
    {"background": "black"},
    {"camera": {"zoom": 1e308}},
    {"camera": {"zoom": 0.0}},
    {"camera": {"pan": [1e300, 0]}},
    {"image_size": 10**9},
    {"generations": 0},
    {"no_such_setting": 1},
]


@pytest.mark.parametrize("settings", BAD_SETTINGS, ids=lambda s: next(iter(s)))
def test_bad_run_settings_are_422_and_write_nothing(client, settings):
    web = client.app.state.web
    before = sorted(p.name for p in web.runs_dir.iterdir())
    r = client.post("/api/runs", json={"volume": "phantom", "settings": settings})
    assert r.status_code == 422, (settings, r.status_code, r.text)
    body = r.json()
    assert body["detail"] and isinstance(body["detail"], str)
    assert sorted(p.name for p in web.runs_dir.iterdir()) == before
    assert not [x for x in client.get("/api/runs").json() if x["name"] not in before]


def test_bad_settings_name_their_field(client):
    r = client.post("/api/runs", json={"volume": "phantom", "settings": {"population": "many"}})
    assert r.status_code == 422
    assert any("population" in ".".join(map(str, e["loc"])) for e in r.json()["errors"])


@pytest.mark.parametrize(
    "camera", [{"zoom": 1e308}, {"zoom": -1}, {"azimuth": float("inf")}, {"pan": [50, 0]}]
)
def test_views_refuse_cameras_out_of_bounds(client, camera):
    tf = {"format": "intuitf.gaussian-tf", "version": 1,
          "gaussians": [{"mean": 0.5, "width": 0.05, "height": 0.5, "color": [1, 1, 1]}]}  # fmt: skip
    body = {"volume": "phantom", "tf": tf, "camera": camera, "size": 32}
    r = client.post("/api/tf/preview", content=_json(body),
                    headers={"Content-Type": "application/json"})  # fmt: skip
    assert r.status_code == 422, r.text
    assert "camera" in r.json()["detail"].lower() or "zoom" in r.json()["detail"].lower()


def _json(obj) -> bytes:
    import json

    return json.dumps(obj, allow_nan=True).encode()


@pytest.mark.parametrize(
    "path", ["/static/app.js%00.png", "/static/%00", "/static/..%2f..%2fpyproject.toml"]
)
def test_static_paths_that_are_no_file_are_404(client, path):
    r = client.get(path)
    assert r.status_code == 404, (path, r.status_code)
    assert r.json()["detail"]


# -- 8: uploads counted as they arrive, one message; uploads can be deleted ---------------------
def _chunked_upload(port: int, token: str, total: int, chunk: int = 64 * 1024):
    """POST /api/volumes with a chunked multipart body of up to ``total`` bytes, sent until
    the server answers; (bytes sent, the answer's status line and body)."""
    import select
    import socket

    boundary = "b0undary"
    head = (
        f'--{boundary}\r\nContent-Disposition: form-data; name="file"; filename="v.raw"\r\n'
        "Content-Type: application/octet-stream\r\n\r\n"
    ).encode()
    sock = socket.create_connection(("127.0.0.1", port), timeout=30)
    sock.sendall(
        (
            "POST /api/volumes HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            f"Authorization: token {token}\r\nTransfer-Encoding: chunked\r\n"
            f"Content-Type: multipart/form-data; boundary={boundary}\r\n\r\n"
        ).encode()
    )
    sent = 0
    payload = head + b"\0" * (chunk - len(head))
    answered = False
    try:
        while sent < total:
            sock.sendall(f"{len(payload):x}\r\n".encode() + payload + b"\r\n")
            sent += len(payload)
            payload = b"\0" * chunk
            if select.select([sock], [], [], 0)[0]:
                answered = True
                break
    except OSError:  # the server closed the connection after answering
        answered = True
    data = b""
    sock.settimeout(10)
    try:
        while b"\r\n\r\n" not in data or not data.rstrip().endswith(b"}"):
            more = sock.recv(65536)
            if not more:
                break
            data += more
    except OSError:
        pass
    sock.close()
    assert answered or data, "the server never answered"
    return sent, data.decode("latin-1")


def test_chunked_upload_stops_at_the_limit_with_one_message(tmp_path):
    import json

    from helpers.web_backend import TOKEN, LiveServer

    app = make_app(tmp_path / "runs", max_upload_bytes=2 * 1024 * 1024)
    with LiveServer(app) as srv:
        sent, answer = _chunked_upload(srv.port, TOKEN, total=256 * 1024 * 1024)
        assert answer.startswith("HTTP/1.1 413"), answer[:200]
        detail = json.loads(answer.split("\r\n\r\n", 1)[1])["detail"]
        assert sent < 16 * 1024 * 1024, f"{sent} bytes were taken before the refusal"
        # A declared length over the limit gets the same words.
        import httpx

        r = httpx.post(srv.url + "/api/volumes", headers=AUTH,
                       files={"file": ("v.raw", b"\0" * (4 * 1024 * 1024))})  # fmt: skip
        assert r.status_code == 413 and r.json()["detail"] == detail
        assert "2 MiB" in detail
    assert not list((tmp_path / "runs" / ".uploads").glob("volumes/*"))


def test_uploaded_volume_can_be_deleted_unless_a_run_uses_it(client):
    import io

    import numpy as np

    def upload(name: str) -> str:
        buf = io.BytesIO()
        np.save(buf, np.arange(16**3, dtype=np.uint8).reshape(16, 16, 16))
        r = client.post("/api/volumes", files={"file": (name, buf.getvalue())})
        assert r.status_code == 201, r.text
        return r.json()["id"]

    vid = upload("gone.npy")
    assert vid in [v["id"] for v in client.get("/api/volumes").json()]
    r = client.delete(f"/api/volumes/{vid}")
    assert r.status_code == 204, r.text
    assert vid not in [v["id"] for v in client.get("/api/volumes").json()]
    assert client.get(f"/api/volumes/{vid}/histogram").status_code == 404
    assert client.delete(f"/api/volumes/{vid}").status_code == 404
    # The built-in phantom and volumes that runs were made from stay.
    r = client.delete("/api/volumes/phantom")
    assert r.status_code == 409 and r.json()["detail"]
    used = upload("used.npy")
    r = client.post("/api/runs", json={"volume": used, "settings": {"generations": 1}})
    assert r.status_code == 201
    wait_run(client, r.json()["name"])
    r = client.delete(f"/api/volumes/{used}")
    assert r.status_code == 409 and r.json()["detail"]
    assert used in [v["id"] for v in client.get("/api/volumes").json()]


# -- 11: a run cut off by a crash says so ------------------------------------------------------
def test_run_cut_off_by_a_crash_is_interrupted_and_resumable(client):
    import json

    name = _start(client, generations=2)
    d = wait_run(client, name)
    assert d["info"]["status"] == "completed"
    registry = client.app.state.web.registry
    _wait(lambda: registry.entry(name) is None, what="the run's folder released")
    # What a killed server leaves: a generation done, no end in the journal, no lock held.
    path = client.app.state.web.store.path_of(name)
    journal = path / "journal.jsonl"
    lines = [ln for ln in journal.read_text().splitlines()
             if json.loads(ln).get("type") not in ("end",)]  # fmt: skip
    gens = [ln for ln in lines if json.loads(ln).get("type") == "generation"]
    lines.remove(gens[-1])
    journal.write_text("\n".join(lines) + "\n")
    events = path / "events.jsonl"
    evs = [ln for ln in events.read_text().splitlines() if '"run_ended"' not in ln]
    events.write_text("\n".join(evs) + "\n")
    d = client.get(f"/api/runs/{name}").json()
    assert d["info"]["status"] == "interrupted", d["info"]
    assert "Resume" in d["info"]["message"]
    listed = {r["name"]: r["status"] for r in client.get("/api/runs").json()}
    assert listed[name] == "interrupted"


# -- 7 and 17: the view socket answers every bad message and stays up; refusals log nothing ------
TF3 = {"format": "intuitf.gaussian-tf", "version": 1, "gaussians": [
    {"mean": 0.3, "width": 0.05, "height": 0.3, "color": [1, 0, 0]},
    {"mean": 0.6, "width": 0.05, "height": 0.5, "color": [0, 1, 0]},
    {"mean": 0.9, "width": 0.05, "height": 0.7, "color": [0, 0, 1]}]}  # fmt: skip


def _bad_messages(qid: str) -> list[str]:
    import json

    good = {"target": {"candidate": qid}, "size": 64}
    return [
        json.dumps({**good, "highlight": [True]}),
        json.dumps({**good, "highlight": [1.5]}),
        json.dumps({**good, "size": "big"}),
        json.dumps({**good, "size": 10**9}),
        json.dumps({**good, "camera": {"zoom": 1e308}}),
        json.dumps({**good, "camera": {"pan": "left"}}),
        json.dumps({**good, "background": [1, 2]}),
        json.dumps({**good, "quality": "ultra"}),
        json.dumps({"target": {"candidate": "nope/g000-000"}, "size": 64}),
        json.dumps({"target": {"volume": "phantom", "tf": {"gaussians": "x"}}, "size": 64}),
        json.dumps({"target": [1, 2]}),
        json.dumps([1, 2, 3]),
        "[" * 100_000,
        "{" * 50_000,
        "not json",
        "x" * 300_000,
    ]


class _Records(__import__("logging").Handler):
    def __init__(self) -> None:
        super().__init__()
        self.messages: list[str] = []

    def emit(self, record) -> None:
        self.messages.append(record.getMessage())


def test_view_socket_answers_every_bad_message_and_stays_up(tmp_path):
    import asyncio
    import json
    import logging

    import websockets

    from helpers.web_backend import TOKEN, LiveServer

    app = make_app(tmp_path / "runs")
    records = _Records()
    for name in ("uvicorn.error", "intuitf.web.app"):
        logging.getLogger(name).addHandler(records)
    try:
        with LiveServer(app) as srv:
            from fastapi.testclient import TestClient

            with TestClient(app, headers=AUTH) as c:
                r = c.post("/api/runs", json={"volume": "phantom", "settings": {"generations": 1}})
                qid = wait_run(c, r.json()["name"])["gallery"][0]["qid"]

            async def talk() -> None:
                url = f"{srv.ws_url}/api/view?token={TOKEN}"
                async with websockets.connect(url, max_size=None) as ws:
                    for text in _bad_messages(qid):
                        await ws.send(text)
                        reply = json.loads(await asyncio.wait_for(ws.recv(), 60))
                        assert reply.get("error"), (text[:80], reply)
                    # Still up: a good request gets its frame.
                    await ws.send(json.dumps({"req": 7, "target": {"candidate": qid}, "size": 64,
                                              "highlight": [0]}))  # fmt: skip
                    header = json.loads(await asyncio.wait_for(ws.recv(), 60))
                    assert header["req"] == 7 and header["format"] == "png", header
                    assert isinstance(await asyncio.wait_for(ws.recv(), 60), bytes)
                # Refused handshakes (no token, another site) are answered, and log nothing.
                for url, headers in [
                    (f"{srv.ws_url}/api/view", {}),
                    (f"{srv.ws_url}/api/view?token={TOKEN}", {"Origin": "http://evil.example"}),
                    (f"{srv.ws_url}/api/view?token=wrong", {}),
                ]:
                    try:
                        async with websockets.connect(url, additional_headers=headers):
                            raise AssertionError("a refused handshake was accepted")
                    except websockets.InvalidStatus as exc:
                        assert exc.response.status_code in (401, 403)

            asyncio.run(talk())
    finally:
        for name in ("uvicorn.error", "intuitf.web.app"):
            logging.getLogger(name).removeHandler(records)
    noise = [m for m in records.messages if "handshake" in m or "Exception in ASGI" in m]
    assert not noise, noise


# -- 12: "Explore from here" takes the query panel's settings, and no second initialize ---------
def test_branch_from_a_candidate_takes_settings_and_skips_initialize(client):
    name = _start(client, generations=3)
    d = wait_run(client, name)
    stages = [g["stage"] for g in client.app.state.web.store.history(name)]
    assert "initialize" in stages
    qid = d["gallery"][0]["qid"]
    cid = qid.split("/")[1]
    r = client.post(
        f"/api/runs/{name}/branch",
        json={
            "candidate": cid,
            "changes": {
                "intent": {"kind": "text", "text": "faint red skin"},
                "settings": {"population": 8, "generations": 2},
                "judge": {"spec": "metric"},
            },
        },
    )
    assert r.status_code == 201, r.text
    child = r.json()["name"]
    d = wait_run(client, child)
    rs = client.app.state.web.run_settings(child)
    assert rs.population == 8 and rs.generations == 2
    stages = [g["stage"] for g in client.app.state.web.store.history(child)]
    assert stages == ["customize", "customize"], stages
    # Bad settings in a branch are refused before anything is made.
    before = len(client.get("/api/runs").json())
    r = client.post(f"/api/runs/{name}/branch",
                    json={"candidate": cid, "changes": {"settings": {"population": "many"}}})  # fmt: skip
    assert r.status_code == 422 and r.json()["detail"]
    assert len(client.get("/api/runs").json()) == before


# -- 13: runs renamed and deleted ----------------------------------------------------------------
def test_runs_can_be_renamed_and_deleted(client):
    name = _start(client, generations=1)
    wait_run(client, name)
    registry = client.app.state.web.registry
    _wait(lambda: registry.entry(name) is None, what="the run's folder released")
    r = client.post(f"/api/runs/{name}/rename", json={"title": "  my   bone run "})
    assert r.status_code == 200, r.text
    assert client.get(f"/api/runs/{name}").json()["info"]["title"] == "my bone run"
    assert {r["name"]: r.get("title") for r in client.get("/api/runs").json()}[
        name
    ] == "my bone run"
    tree = client.get("/api/tree").json()
    assert any(n["run"]["name"] == name and n["run"]["title"] == "my bone run" for n in tree)
    assert client.post(f"/api/runs/{name}/rename", json={"title": ""}).status_code == 422
    # A run with branches stays until they go; a going run cannot be deleted.
    qid = client.get(f"/api/runs/{name}").json()["gallery"][0]["qid"]
    r = client.post(f"/api/runs/{name}/branch",
                    json={"candidate": qid.split("/")[1], "changes": {"settings": {"generations": 1}}})  # fmt: skip
    child = r.json()["name"]
    assert client.delete(f"/api/runs/{child}").status_code == 409  # still going
    wait_run(client, child)
    _wait(lambda: registry.entry(child) is None, what="the branch's folder released")
    r = client.delete(f"/api/runs/{name}")
    assert r.status_code == 409 and child in r.json()["detail"]
    assert client.delete(f"/api/runs/{child}").status_code == 204
    assert client.delete(f"/api/runs/{name}").status_code == 204
    names = [r["name"] for r in client.get("/api/runs").json()]
    assert name not in names and child not in names
    assert client.get(f"/api/runs/{name}").status_code == 404
    runs_dir = client.app.state.web.runs_dir
    assert [p for p in (runs_dir / ".deleted").iterdir() if p.name.startswith(name + "-")]


# -- 14: near-duplicates folded in the gallery ---------------------------------------------------
def test_gallery_folds_near_duplicates():
    from intuitf.tf import GaussianTF
    from intuitf.web.routes_runs import fold_gallery

    def tf(mean, height=0.5):
        return GaussianTF.from_dict({"format": "intuitf.gaussian-tf", "version": 1, "gaussians": [
            {"mean": mean, "width": 0.05, "height": height, "color": [1, 0.5, 0.2]}]})  # fmt: skip

    tfs = {"a": tf(0.3), "b": tf(0.3005), "c": tf(0.7), "d": tf(0.3, 0.501), "e": tf(0.5)}
    ratings = {"a": 1600.0, "b": 1590.0, "c": 1500.0, "d": 1400.0, "e": float("nan")}
    out = fold_gallery("run", ["a", "b", "c", "d", "e"], tfs, ratings)
    assert [g["id"] for g in out] == ["a", "c", "e"]
    assert out[0]["similar"] == ["b", "d"] and out[1]["similar"] == []
    assert [g["rank"] for g in out] == [1, 3, 5] and out[2]["rating"] is None


def test_history_thumbnails_point_at_pictures_that_exist(client):
    name = _start(client, generations=1)
    wait_run(client, name)
    for node in client.get("/api/tree").json():
        for g in node["generations"]:
            if g["thumbnail"]:
                assert client.get(g["thumbnail"]).status_code == 200


# -- 15: features are labelled with the volume's structures --------------------------------------
def test_volume_structures_label_the_features(client):
    r = client.get("/api/volumes/phantom/structures")
    assert r.status_code == 200, r.text
    parts = r.json()
    assert parts and all(0 <= p["value_range"][0] <= p["value_range"][1] <= 1 for p in parts)
    assert all(p["shape"] and p["position"] for p in parts)
    assert client.get("/api/volumes/nope/structures").status_code == 404


# -- 16: Export PNG of the view on screen ----------------------------------------------------------
def test_export_png_of_the_current_view(client):
    import json

    name = _start(client, generations=1)
    qid = wait_run(client, name)["gallery"][0]["qid"]
    run, cid = qid.split("/")
    judging = client.get(f"/api/export/{run}/{cid}?to=png&size=64")
    assert judging.status_code == 200 and judging.headers["content-type"] == "image/png"
    cam = json.dumps({"azimuth": 120, "elevation": -30, "zoom": 1.5, "pan": [0, 0]})
    turned = client.get(f"/api/export/{run}/{cid}", params={"to": "png", "size": 64, "camera": cam})
    assert turned.status_code == 200 and turned.content != judging.content
    bad = client.get(f"/api/export/{run}/{cid}", params={"to": "png", "camera": "{zoom"})
    assert bad.status_code == 422 and bad.json()["detail"]
    far = client.get(f"/api/export/{run}/{cid}",
                     params={"to": "png", "camera": json.dumps({"zoom": 1e308})})  # fmt: skip
    assert far.status_code == 422


def test_docs_page_dropped_schema_declares_the_error_body(client):
    assert client.get("/docs").status_code == 404
    schema = client.get("/openapi.json").json()
    assert "ErrorOut" in schema["components"]["schemas"]
    post = schema["paths"]["/api/runs"]["post"]["responses"]
    for status in ("404", "409", "413", "422", "429"):
        ref = post[status]["content"]["application/json"]["schema"]["$ref"]
        assert ref.endswith("/ErrorOut"), (status, ref)
    run_in = schema["components"]["schemas"]["RunIn"]
    assert run_in.get("additionalProperties") is False
