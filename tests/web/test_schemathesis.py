"""Property-based API tests from the OpenAPI schema: no request makes the server fail (5xx),
and every answer is one the schema declares (status, content type, body).

Runs in process against the ASGI app with the token; the app's runs are tiny (population 6,
2 generations, 48-pixel pictures) and at most two go at once, so requests that happen to
start runs stay cheap. The SSE stream never ends, so it is left to test_sse_ws.py.
"""

from __future__ import annotations

import pytest

schemathesis = pytest.importorskip("schemathesis")

from hypothesis import HealthCheck, settings  # noqa: E402
from schemathesis.specs.openapi.checks import positive_data_acceptance  # noqa: E402

from helpers.web_backend import AUTH, make_app  # noqa: E402

_app_holder: dict = {}


def _app():
    if "app" not in _app_holder:
        import tempfile

        _app_holder["app"] = make_app(tempfile.mkdtemp(prefix="intuitf-schema-"), max_live_runs=2)
    return _app_holder["app"]


schema = schemathesis.openapi.from_asgi("/openapi.json", _app(), headers=AUTH)


@pytest.fixture(scope="module", autouse=True)
def _lifespan():
    """Run the app's startup and shutdown around the tests (live runs are closed at the end)."""
    from fastapi.testclient import TestClient

    with TestClient(_app(), headers=AUTH) as c:
        # One finished run, so that ids the schema's examples hit can exist.
        r = c.post("/api/runs", json={"volume": "phantom", "name": "string"})
        assert r.status_code == 201
        yield


@pytest.mark.slow
@schema.exclude(path="/api/runs/{name}/events").parametrize()
@settings(
    max_examples=20,
    deadline=None,
    suppress_health_check=list(HealthCheck),
    derandomize=True,
    database=None,
)
def test_no_server_errors(case):
    response = case.call(headers=AUTH)
    # The token and the Host are right, so the API itself answers every case.
    assert response.status_code != 401, response.text
    assert "Host" not in response.text[:60], response.text
    # Every check (no 5xx; declared status, content type and body) but one: a request the
    # schema allows may still be refused for what no schema can say (an empty file is no
    # volume, "" is no candidate), with a declared 4xx and its message.
    case.validate_response(response, excluded_checks=[positive_data_acceptance])
