"""The web API in process (Starlette's TestClient): runs, history, views, verdicts, edits."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from helpers.web_backend import AUTH, SMALL, make_app, wait_run
from intuitf.session.views import pick_bar

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = make_app(tmp_path_factory.mktemp("runs"))
    with TestClient(app, headers=AUTH) as c:
        yield c


@pytest.fixture(scope="module")
def done_run(client) -> dict:
    r = client.post(
        "/api/runs",
        json={
            "volume": "phantom",
            "name": "head",
            "intent": {"kind": "text", "text": "white bone"},
        },
    )
    assert r.status_code == 201, r.text
    name = r.json()["name"]
    d = wait_run(client, name)
    assert d["info"]["status"] == "completed", d
    return d


def _png(resp) -> np.ndarray:
    assert resp.status_code == 200, resp.text
    assert resp.headers["content-type"] == "image/png"
    assert resp.content.startswith(PNG_MAGIC)
    return np.asarray(Image.open(io.BytesIO(resp.content)))


def _upload_png(client, arr: np.ndarray) -> dict:
    buf = io.BytesIO()
    Image.fromarray(arr).save(buf, format="PNG")
    r = client.post("/api/uploads", files={"file": ("p.png", buf.getvalue(), "image/png")})
    assert r.status_code == 201, r.text
    return r.json()


def test_info_and_volumes(client):
    info = client.get("/api/info").json()
    assert info["evaluator"] == "metric" and "metric" in info["evaluators"]
    vols = client.get("/api/volumes").json()
    ph = next(v for v in vols if v["id"] == "phantom")
    assert ph == {"id": "phantom", "name": "phantom", "shape": [96, 96, 96], "dtype": "uint8",
                  "source": "builtin", "spacing": None}  # fmt: skip
    h = client.get("/api/volumes/phantom/histogram").json()
    assert len(h["counts"]) == 256 and max(h["counts"]) == pytest.approx(1.0)
    assert h["value_range"][0] < h["value_range"][1]
    assert h["materials"] and all(0 <= m["mean"] <= 1 and m["width"] > 0 for m in h["materials"])


def test_finished_run_detail_gallery_and_tree(client, done_run):
    name = done_run["info"]["name"]
    assert name == "head"
    assert done_run["info"]["generations_done"] == 2
    gallery = done_run["gallery"]
    assert 1 <= len(gallery) <= 8
    assert [g["rank"] for g in gallery] == sorted(g["rank"] for g in gallery)
    assert all(g["qid"] == f"{name}/{g['id']}" for g in gallery)
    # The page draws a sketch over the run's judging view, and finds its volume by id.
    from intuitf.session.building import default_camera
    from intuitf.volume.phantom import phantom

    # The camera the run judged from: the session's default for the volume, as every front
    # end's (the run named no camera).
    assert done_run["camera"] == default_camera(phantom())
    volume_ids = [v["id"] for v in client.get("/api/volumes").json()]
    assert done_run["volume_id"] in volume_ids
    # The page previews a volume from the same view, before any run.
    got = client.get(f"/api/volumes/{done_run['volume_id']}/camera")
    assert got.status_code == 200 and got.json()["camera"] == done_run["camera"]
    assert client.get("/api/volumes/no-such-volume/camera").status_code == 404
    runs = client.get("/api/runs").json()
    assert any(r["name"] == name and r["status"] == "completed" for r in runs)
    tree = client.get("/api/tree").json()
    node = next(n for n in tree if n["run"]["name"] == name)
    gens = node["generations"]
    assert [g["generation"] for g in gens] == [0, 1]
    assert gens[0]["thumbnail"] == f"/api/runs/{name}/generations/0/thumbnail"
    img = _png(client.get(gens[0]["thumbnail"]))
    assert img.shape[:2] == (SMALL["image_size"],) * 2


def test_matches_carry_verdicts_and_reasons(client, done_run):
    name = done_run["info"]["name"]
    ms = client.get(f"/api/runs/{name}/matches", params={"generation": 0}).json()
    assert len(ms) >= 3
    m = ms[0]
    assert set(m) >= {"round", "first", "second", "winner", "p_first", "per_aspect", "reasons",
                      "error", "source"}  # fmt: skip
    assert m["source"] == "model" and m["winner"] in ("first", "second", "tie")
    assert m["first"].startswith("g000-") and m["reasons"]


def test_candidate_views_and_exports(client, done_run):
    qid = done_run["gallery"][0]["qid"]
    run, cid = qid.split("/")
    c = client.get(f"/api/candidates/{qid}").json()
    assert c["qid"] == qid and c["tf"]["format"] == "intuitf.gaussian-tf"
    n = len(c["tf"]["gaussians"])
    assert _png(client.get(f"/api/candidates/{qid}/image")).shape[:2] == (48, 48)
    assert _png(client.get(f"/api/candidates/{qid}/image", params={"size": 64})).shape[:2] == (
        64,
        64,
    )
    cam = {"azimuth": 30, "elevation": 10}
    pick = client.post(
        f"/api/candidates/{qid}/pick", json={"camera": cam, "x": 32, "y": 32, "size": 64}
    ).json()
    assert pick["index"] is not None and 0 <= pick["index"] < n
    # The paper's rule: the smallest of the features that hold enough of the pixel (the
    # visible list is sorted by area; one that makes too little of the pixel is passed).
    bar = pick_bar([tuple(v) for v in pick["visible"]])
    assert pick["index"] == next(i for i, share, _ in pick["visible"] if share >= bar)
    assert pick["mask"].startswith("data:image/png;base64,")
    assert pick["selected"] == [pick["index"]]
    # A whole pick (a double-click) selects every feature that makes the pixel.
    whole = client.post(
        f"/api/candidates/{qid}/pick",
        json={"camera": cam, "x": 32, "y": 32, "size": 64, "whole": True},
    ).json()
    assert whole["index"] == pick["index"] and whole["visible"] == pick["visible"]
    assert whole["selected"] == sorted(int(i) for i, share, _ in pick["visible"] if share >= bar)
    feats = client.post(f"/api/candidates/{qid}/features", json={"camera": cam, "size": 48}).json()
    assert [f["index"] for f in feats] == list(range(n))
    assert all(f["image"].startswith("data:image/png;base64,") for f in feats)
    for fmt, needle in (("paraview", b"RGBPoints"), ("slicer", b""), ("vtk", b"vtk"),
                        ("1dt", b""), ("json", b"intuitf.gaussian-tf")):  # fmt: skip
        r = client.get(f"/api/export/{qid}", params={"to": fmt})
        assert r.status_code == 200, r.text
        assert "attachment" in r.headers["content-disposition"]
        assert f"{run}-{cid}" in r.headers["content-disposition"]
        assert needle in r.content and r.content
    tf = json.loads(client.get(f"/api/export/{qid}", params={"to": "json"}).content)
    value_range = client.get("/api/volumes/phantom/histogram").json()["value_range"]
    assert tf["gaussians"] == c["tf"]["gaussians"] and tf["value_range"] == value_range
    _png(client.get(f"/api/export/{qid}", params={"to": "png", "size": 64}))
    assert client.get(f"/api/export/{qid}", params={"to": "exe"}).status_code == 422


def test_tf_preview(client, done_run):
    tf = client.get(f"/api/candidates/{done_run['gallery'][0]['qid']}").json()["tf"]
    body = {"volume": "phantom", "tf": tf, "camera": {"azimuth": 90, "orthographic": True},
            "size": 40, "shaded": False, "background": [1, 1, 1]}  # fmt: skip
    img = _png(client.post("/api/tf/preview", json=body))
    assert img.shape[:2] == (40, 40)
    assert (img[0, 0, :3] == 255).all()  # a white background in the corner
    bad = client.post("/api/tf/preview", json={**body, "tf": {"format": "nope"}})
    assert bad.status_code == 422 and "transfer function" in bad.json()["detail"]


def test_human_verdicts_on_a_finished_run(client, done_run):
    name = done_run["info"]["name"]
    ids = [g["id"] for g in done_run["gallery"]]
    last = ids[-1]
    r = client.post(f"/api/runs/{name}/prefer", json={"better": last, "worse": ids[0]})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["verdict"]["kind"] == "prefer" and body["verdict"]["winners"] == [last]
    assert body["ranking"].index(last) < body["ranking"].index(ids[0])
    r = client.post(f"/api/runs/{name}/worst", json={"worst": ids[1], "among": ids[:3]})
    assert r.status_code == 200 and r.json()["verdict"]["losers"] == [ids[1]]
    r = client.post(f"/api/runs/{name}/best", json={"best": ids[2], "among": ids[:3]})
    assert r.status_code == 200
    ms = client.get(f"/api/runs/{name}/matches").json()
    human = [m for m in ms if m["source"] == "human"]
    assert human and any(m["first"] == last for m in human)
    for _ in range(3):
        assert client.post(f"/api/runs/{name}/undo", json={}).status_code == 200
    r = client.post(f"/api/runs/{name}/undo", json={})
    assert r.status_code == 422 and "no verdict" in r.json()["detail"]
    assert client.post(f"/api/runs/{name}/prefer", json={"better": "g999-999", "worse": last}
                       ).status_code == 422  # fmt: skip
    # the gallery now follows the model's ranking again
    assert [g["id"] for g in client.get(f"/api/runs/{name}").json()["gallery"]] == ids


def test_hand_edit_is_a_point_of_the_history(client, done_run):
    name = done_run["info"]["name"]
    qid = done_run["gallery"][0]["qid"]
    tf = client.get(f"/api/candidates/{qid}").json()["tf"]
    tf["gaussians"][0]["height"] = min(1.0, tf["gaussians"][0]["height"] * 0.5 + 0.01)
    r = client.post("/api/edits", json={"parent": qid, "tf": tf})
    assert r.status_code == 201, r.text
    eq = r.json()["qid"]
    assert eq.endswith("/g000-000") and eq.startswith("edit")
    got = client.get(f"/api/candidates/{eq}").json()
    assert got["tf"]["gaussians"] == tf["gaussians"] and got["parents"] == [qid]
    gallery = client.get(f"/api/runs/{eq.split('/')[0]}").json()["gallery"]
    assert [g["qid"] for g in gallery] == [eq]
    info = next(r for r in client.get("/api/runs").json() if r["name"] == eq.split("/")[0])
    assert info["parent"]["run"] == name and info["status"] == "edited"
    tree = client.get("/api/tree").json()
    node = next(n for n in tree if n["run"]["name"] == name)
    assert any(ch["run"]["name"] == eq.split("/")[0] for ch in node["children"])
    assert client.post(f"/api/runs/{eq.split('/')[0]}/continue").status_code == 409
    # a branch starts from the edited TF like from any candidate
    r = client.post(f"/api/runs/{eq.split('/')[0]}/branch", json={"candidate": "g000-000"})
    assert r.status_code == 201, r.text
    d = wait_run(client, r.json()["name"])
    assert d["info"]["status"] == "completed"
    assert d["info"]["parent"]["run"] == eq.split("/")[0]
    bad = client.post("/api/edits", json={"parent": "../../etc/g000-000", "tf": tf})
    assert bad.status_code == 404


def test_refine_selected_gaussians_branches(client, done_run):
    name = done_run["info"]["name"]
    cid = done_run["gallery"][0]["id"]
    r = client.post(
        f"/api/runs/{name}/refine",
        json={"candidate": cid, "selected": [0], "text": "make it red", "generations": 1},
    )
    assert r.status_code == 201, r.text
    child = r.json()["name"]
    d = wait_run(client, child)
    assert d["info"]["status"] == "completed", d
    assert d["info"]["parent"]["run"] == name and d["info"]["parent"]["candidate"] == cid
    assert d["info"]["intent"]["kind"] == "edit" and d["info"]["intent"]["selected"] == [0]
    r = client.post(
        f"/api/runs/{name}/refine", json={"candidate": cid, "selected": [99], "text": "red"}
    )
    assert r.status_code == 422


def test_branch_from_a_generation(client, done_run):
    name = done_run["info"]["name"]
    r = client.post(f"/api/runs/{name}/branch", json={"generation": 1})
    assert r.status_code == 201, r.text
    d = wait_run(client, r.json()["name"])
    assert d["info"]["status"] == "completed" and d["info"]["parent"]["generation"] == 1


@pytest.mark.slow
def test_query_continue_cancel_and_pause(client):
    r = client.post("/api/runs", json={"volume": "phantom", "settings": {"generations": 6}})
    assert r.status_code == 201
    name = r.json()["name"]
    assert client.post(f"/api/runs/{name}/pause").json()["status"] in ("paused", "idle", "running")
    assert client.post(f"/api/runs/{name}/proceed").status_code == 200
    assert client.post(f"/api/runs/{name}/cancel").status_code == 200
    d = wait_run(client, name)
    assert d["info"]["status"] == "cancelled", d["info"]
    assert client.post(f"/api/runs/{name}/cancel").status_code == 409
    r = client.post(f"/api/runs/{name}/continue", json={})
    assert r.status_code == 200, r.text
    assert client.post(f"/api/runs/{name}/continue", json={}).status_code == 409
    d = wait_run(client, name)
    assert d["info"]["status"] == "completed" and d["info"]["generations_done"] == 6
    assert client.post(f"/api/runs/{name}/continue").status_code == 409  # all done
    # a query on a finished run opens a new customize stage and runs it
    r = client.post(
        f"/api/runs/{name}/query",
        json={"intent": {"kind": "text", "text": "faint red skin"}, "generations": 1},
    )
    assert r.status_code == 202, r.text
    d = wait_run(client, name)
    assert d["info"]["status"] == "completed" and d["info"]["generations_done"] == 7


def test_pictures_and_intents(client, done_run):
    ref = np.zeros((40, 40, 3), np.uint8)
    ref[..., 0] = 200
    up = _upload_png(client, ref)
    assert up["width"] == 40 and up["height"] == 40
    r = client.post(
        "/api/runs",
        json={"volume": "phantom", "settings": {"generations": 1},
              "intent": {"kind": "image", "reference": f"upload:{up['id']}"}},
    )  # fmt: skip
    assert r.status_code == 201, r.text
    assert wait_run(client, r.json()["name"])["info"]["intent"]["has_reference"]
    sketch = np.zeros((48, 48, 4), np.uint8)
    sketch[10:20, 10:20] = (255, 0, 0, 255)
    sk = _upload_png(client, sketch)
    r = client.post(
        "/api/runs",
        json={"volume": "phantom", "settings": {"generations": 1},
              "intent": {"kind": "sketch", "sketch": f"upload:{sk['id']}",
                         "base": f"candidate:{done_run['gallery'][0]['qid']}"}},
    )  # fmt: skip
    assert r.status_code == 201, r.text
    d = wait_run(client, r.json()["name"])
    assert d["info"]["intent"]["has_sketch"] and d["info"]["intent"]["has_base"]
    bad = client.post("/api/uploads", files={"file": ("x.png", b"not a picture", "image/png")})
    assert bad.status_code == 422 and bad.json()["hint"]
    r = client.post(
        "/api/runs",
        json={"volume": "phantom", "intent": {"kind": "image", "reference": "/etc/hosts"}},
    )
    assert r.status_code == 422 and "upload id" in r.json()["detail"]
    r = client.post(
        "/api/runs",
        json={"volume": "phantom", "intent": {"kind": "image", "reference": "upload:0123"}},
    )
    assert r.status_code == 404


def test_volume_upload(client):
    arr = (np.arange(20 * 18 * 16) % 97).reshape(20, 18, 16).astype(np.uint8)
    buf = io.BytesIO()
    np.save(buf, arr)
    r = client.post("/api/volumes", files={"file": ("tiny blob.npy", buf.getvalue())})
    assert r.status_code == 201, r.text
    v = r.json()
    assert v["source"] == "upload" and v["shape"] == [16, 18, 20] and v["dtype"] == "uint8"
    assert any(x["id"] == v["id"] for x in client.get("/api/volumes").json())
    assert client.get(f"/api/volumes/{v['id']}/histogram").status_code == 200
    bad = client.post("/api/volumes", files={"file": ("broken.npy", b"garbage")})
    assert bad.status_code == 422 and "broken.npy" in bad.json()["detail"]
    assert "/" not in bad.json()["detail"].split("broken.npy")[0][-3:]
    bad = client.post("/api/volumes", files={"file": ("x.exe", b"MZ")})
    assert bad.status_code == 422


def test_errors_are_json_with_a_message(client):
    for path in ("/api/runs/nope", "/api/candidates/nope/g000-000", "/api/runs/nope/matches",
                 "/api/candidates/head/notanid", "/api/volumes/nope/histogram"):  # fmt: skip
        r = client.get(path)
        assert r.status_code == 404, path
        assert isinstance(r.json()["detail"], str)
    r = client.post("/api/runs", json={"volume": "phantom", "settings": {"populaton": 8}})
    assert r.status_code == 422 and "populaton" in r.json()["detail"]
    r = client.post("/api/runs", json={"volume": "phantom", "settings": {"population": 2}})
    assert r.status_code == 422 and "population" in r.json()["detail"]
    r = client.post("/api/runs", json={"volume": "phantom", "judge": "nosuch:model"})
    assert r.status_code == 422 and r.json()["detail"]
    r = client.post("/api/runs", json={"vol": "phantom"})
    assert r.status_code == 422 and isinstance(r.json()["detail"], str)
    assert client.post("/api/runs/nope/pause").status_code == 404


def test_query_on_a_live_run_starts_a_stage_at_the_next_boundary(client):
    r = client.post(
        "/api/runs",
        json={"volume": "phantom", "intent": "white bone", "settings": {"generations": 3}},
    )
    name = r.json()["name"]
    r = client.post(
        f"/api/runs/{name}/query",
        json={"intent": {"kind": "text", "text": "faint red skin"}, "generations": 1},
    )
    assert r.status_code == 202, r.text
    assert r.json()["status"] == "running"
    d = wait_run(client, name)
    assert d["info"]["status"] == "completed", d["info"]
    # the journal has the query, and the run's plan ends with its customize stage
    with client.stream("GET", f"/api/runs/{name}/events") as s:
        body = ""
        for chunk in s.iter_text():
            body += chunk
            if "event: run_ended" in body:
                break
    assert "event: query" in body and "faint red skin" in body
    assert d["info"]["generations_done"] in (2, 3)


def test_a_failing_run_says_how_it_ended_before_it_stops_being_live(client, monkeypatch):
    """A status read between the two must not find a run cut off by a crash ("interrupted")."""
    from intuitf.session.events import EventLog
    from intuitf.session.live import LiveSession

    async def broken(self):
        raise RuntimeError("kaboom")

    live_at_end: list[bool] = []
    emit = EventLog.emit

    def watching(self, type, **data):
        if type == "run_ended":
            entry = client.app.state.web.registry.entry("broken-order")
            live_at_end.append(entry is not None and entry.live)
        return emit(self, type, **data)

    monkeypatch.setattr(LiveSession, "astep", broken)
    monkeypatch.setattr(EventLog, "emit", watching)
    r = client.post("/api/runs", json={"volume": "phantom", "name": "broken-order"})
    d = wait_run(client, r.json()["name"])
    assert d["info"]["status"] == "error"
    assert live_at_end == [True]


def test_a_run_that_fails_says_so_in_its_events(client, monkeypatch):
    from intuitf.session.live import LiveSession

    async def broken(self):
        raise RuntimeError("kaboom")

    monkeypatch.setattr(LiveSession, "astep", broken)
    r = client.post("/api/runs", json={"volume": "phantom", "name": "broken"})
    name = r.json()["name"]
    d = wait_run(client, name)
    assert d["info"]["status"] == "error" and "kaboom" in d["info"]["message"]
    monkeypatch.undo()
    with client.stream("GET", f"/api/runs/{name}/events") as s:
        body = ""
        for chunk in s.iter_text():
            body += chunk
            if "event: run_ended" in body:
                break
    assert '"reason":"error"' in body and "kaboom" in body
    assert client.get("/api/info").status_code == 200  # the server goes on


def test_a_run_beyond_the_servers_limit_is_a_429_and_writes_nothing(tmp_path):
    app = make_app(tmp_path / "runs", max_live_runs=1)
    with TestClient(app, headers=AUTH) as c:
        first = c.post("/api/runs", json={"volume": "phantom", "settings": {"generations": 50}})
        assert first.status_code == 201, first.text
        name = first.json()["name"]
        assert c.post(f"/api/runs/{name}/pause").status_code == 200  # it stays going
        before = sorted(p.name for p in (tmp_path / "runs").iterdir())
        second = c.post("/api/runs", json={"volume": "phantom", "name": "second"})
        assert second.status_code == 429, second.text
        body = second.json()
        assert body["detail"].startswith("1 run is going already")
        assert "pause or stop one" in body["hint"]
        assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == before
        # The run going already cannot be continued a second time: a 409.
        again = c.post(f"/api/runs/{name}/continue", json={})
        assert again.status_code == 409, again.text
        assert c.post(f"/api/runs/{name}/cancel").status_code == 200
        wait_run(c, name)
