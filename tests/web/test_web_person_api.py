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
