"""Safe by default: the token everywhere, Host and Origin checks, CSP, upload limits, no paths
from the browser, and no API key in any response."""

from __future__ import annotations

import io

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image
from starlette.testclient import WebSocketDenialResponse

from helpers.web_backend import AUTH, TOKEN, make_app, wait_run
from intuitf.web.security import CSP

ROUTES = ["/", "/api/info", "/api/volumes", "/api/runs", "/api/tree", "/openapi.json", "/docs",
          "/static/app.js", "/api/runs/x/events"]  # fmt: skip


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    return make_app(tmp_path_factory.mktemp("runs"), max_upload_bytes=200_000)


@pytest.fixture(scope="module")
def anon(app):
    with TestClient(app) as c:
        yield c


@pytest.mark.parametrize("path", ROUTES)
def test_no_token_is_401_everywhere(anon, path):
    r = anon.get(path)
    assert r.status_code == 401
    assert r.json()["detail"] and r.json()["hint"]
    r = anon.get(path, headers={"Authorization": "token wrong-token"})
    assert r.status_code == 401
    r = anon.get(path, headers={"Cookie": "intuitf_token=wrong"})
    assert r.status_code == 401
    assert anon.post("/api/runs", json={"volume": "phantom"}).status_code == 401


def test_websocket_needs_the_token(anon):
    with pytest.raises(WebSocketDenialResponse) as err:
        with anon.websocket_connect("/api/view"):
            pass
    assert err.value.status_code == 401
    with anon.websocket_connect(f"/api/view?token={TOKEN}") as ws:
        ws.send_text("[]")
        assert "error" in ws.receive_json()


def test_token_in_the_url_sets_a_cookie_that_works(app):
    with TestClient(app) as c:
        r = c.get(f"/api/info?token={TOKEN}")
        assert r.status_code == 200
        cookie = r.headers["set-cookie"]
        assert cookie.startswith(f"intuitf_token={TOKEN}")
        assert "HttpOnly" in cookie and "SameSite=Strict" in cookie and "Path=/" in cookie
        # the client keeps the cookie: later requests need nothing else
        assert c.get("/api/info").status_code == 200
        assert c.get("/openapi.json").status_code == 200
        assert "set-cookie" not in c.get(f"/api/info?token={TOKEN}").headers
    with TestClient(app) as c:
        assert c.get("/api/info", headers=AUTH).status_code == 200
        assert "set-cookie" not in c.get("/api/info", headers=AUTH).headers
        assert c.get("/api/info", headers={"Authorization": f"Bearer {TOKEN}"}).status_code == 200


def test_bad_host_is_400(app):
    with TestClient(app, headers=AUTH) as c:
        for host in ("evil.example", "attacker.test:8000", "127.0.0.2", ""):
            r = c.get("/api/info", headers={"host": host})
            assert r.status_code == 400, host
            assert "Host" in r.json()["detail"]
    strict = make_app_for_port()
    with TestClient(strict, base_url="http://127.0.0.1:8123", headers=AUTH) as c:
        assert c.get("/api/info").status_code == 200
        assert c.get("/api/info", headers={"host": "127.0.0.1:9999"}).status_code == 400
        assert c.get("/api/info", headers={"host": "localhost:8123"}).status_code == 200


def make_app_for_port():
    import tempfile

    return make_app(tempfile.mkdtemp(), allowed_hosts=["127.0.0.1:8123", "localhost:8123"])


def test_cross_origin_writes_and_websocket_are_403(app):
    with TestClient(app, headers=AUTH) as c:
        for origin in ("http://evil.example", "null", "http://testserver.evil.example",
                       "https://localhost:1"):  # fmt: skip
            r = c.post("/api/runs", json={"volume": "phantom"}, headers={"Origin": origin})
            assert r.status_code == 403, origin
            with pytest.raises(WebSocketDenialResponse) as err:
                with c.websocket_connect("/api/view", headers={"Origin": origin}):
                    pass
            assert err.value.status_code == 403
        # the page's own origin is fine
        r = c.post("/api/runs/none/pause", headers={"Origin": "http://testserver"})
        assert r.status_code == 404
        with c.websocket_connect("/api/view", headers={"Origin": "http://testserver"}) as ws:
            ws.send_text("{}")
            assert ws.receive_json()["error"]
        # reads carry no CORS permission for anyone
        r = c.get("/api/info", headers={"Origin": "http://evil.example"})
        assert not any(h.lower().startswith("access-control-") for h in r.headers)
        r = c.options("/api/runs", headers={"Origin": "http://evil.example",
                                            "Access-Control-Request-Method": "POST"})  # fmt: skip
        assert not any(h.lower().startswith("access-control-") for h in r.headers)


def test_csp_and_security_headers(app, anon):
    with TestClient(app, headers=AUTH) as c:
        for path in ("/", "/api/info", "/api/runs/nope", "/openapi.json"):
            r = c.get(path)
            assert r.headers["content-security-policy"] == CSP, path
            assert r.headers["x-content-type-options"] == "nosniff"
            assert r.headers["x-frame-options"] == "DENY"
            assert r.headers["referrer-policy"] == "no-referrer"
    assert anon.get("/").headers["content-security-policy"] == CSP
    assert "'unsafe-inline'" not in CSP and "script-src 'self'" in CSP


def test_upload_too_large_is_413(app):
    big = b"\0" * 300_000
    with TestClient(app, headers=AUTH) as c:
        for path in ("/api/uploads", "/api/volumes"):
            r = c.post(path, files={"file": ("big.raw", big)})
            assert r.status_code == 413, path
            assert "limit" in r.json()["detail"]
        # a picture over the pixel limit is refused without being decoded
        buf = io.BytesIO()
        Image.fromarray(np.zeros((4200, 4200), np.uint8)).save(buf, format="PNG")
        assert len(buf.getvalue()) < 200_000
        r = c.post("/api/uploads", files={"file": ("bomb.png", buf.getvalue(), "image/png")})
        assert r.status_code == 413 and "pixels" in r.json()["detail"]


def test_a_path_is_never_a_volume_or_a_run(app):
    with TestClient(app, headers=AUTH) as c:
        for vol in ("/etc/passwd", "../../etc/passwd", "phantom/../../x", "~/data.raw",
                    "C:\\x.raw", "builtin:phantom"):  # fmt: skip
            r = c.post("/api/runs", json={"volume": vol})
            assert r.status_code in (404, 422), vol
        r = c.post("/api/runs", json={"volume": {"source": "/etc/passwd"}})
        assert r.status_code == 422
        for path in ("/api/volumes/..%2F..%2Fetc%2Fpasswd/histogram",
                     "/api/runs/..%2F..%2Fetc", "/api/candidates/..%2Fx/g000-000",
                     "/api/candidates/..%2F..%2Fetc%2Fpasswd", "/static/../app.py",
                     "/static/..%2F..%2Fapp.py", "/api/runs/.uploads",
                     "/api/runs/..%2F/generations/0/thumbnail"):  # fmt: skip
            r = c.get(path)
            assert r.status_code in (404, 422), path
            assert b"root:" not in r.content and b"def create_app" not in r.content
        r = c.post("/api/tf/preview", json={"volume": "/etc/passwd", "tf": {}})
        assert r.status_code in (404, 422)
        r = c.post("/api/runs/x/branch", json={"changes": {"volume": "/etc/passwd"}})
        assert r.status_code == 404


def test_api_keys_never_reach_a_response(tmp_path, monkeypatch):
    secret = "sk-test-SECRET-never-shown-0123456789"
    monkeypatch.setenv("OPENAI_API_KEY", secret)
    monkeypatch.setenv("INTUITF_API_KEY", secret + "-url")
    app = make_app(tmp_path / "runs", evaluator="openai:gpt-4o")
    seen: list[bytes] = []
    with TestClient(app, headers=AUTH) as c:

        def get(path, **kw):
            r = c.get(path, **kw)
            seen.append(r.content + str(r.headers).encode())
            return r

        def post(path, **kw):
            r = c.post(path, **kw)
            seen.append(r.content + str(r.headers).encode())
            return r

        get("/api/info")
        # A run whose model server is unreachable ends with a message, keys kept out of it.
        r = post(
            "/api/runs",
            json={"volume": "phantom", "judge": {"spec": "openai:gpt-4o",
                  "base_url": f"http://user:{secret}@127.0.0.1:9/v1", "budget_calls": 3,
                  "options": {"timeout": 1, "deadline": 2}}},
        )  # fmt: skip
        assert r.status_code in (201, 422), r.text
        if r.status_code == 201:
            name = r.json()["name"]
            wait_run(c, name)
            get(f"/api/runs/{name}")
            get(f"/api/runs/{name}/matches")
            with c.stream("GET", f"/api/runs/{name}/events?since=0") as s:
                body = b""
                for chunk in s.iter_bytes():
                    body += chunk
                    if b"run_ended" in body:
                        break
                seen.append(body)
        # Even text that echoes what was sent is blanked.
        post("/api/runs", json={"volume": "phantom", "name": secret})
        post("/api/runs", json={"volume": secret})
        get("/api/runs")
        get("/api/tree")
        get("/openapi.json")
    blob = b"\n".join(seen)
    assert secret.encode() not in blob
    assert b"SECRET-never-shown" not in blob
