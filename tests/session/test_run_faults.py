"""A run whose judge fails some matches goes on with them undecided; a judge that is down
ends the run with reason "judge" and a message that says so."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from intuitf.session import Session
from intuitf.testing.fake_mllm import FakeMLLMServer
from intuitf.volume import phantom

SETTINGS = dict(population=8, generations=2, seed=2, image_size=40, output_size=48, top_k=1)


@pytest.fixture(scope="module")
def vol():
    return phantom(size=40)


def _spec(url: str) -> dict:
    # No retries: every fault the server injects fails its match outright.
    return {"volume": "phantom", "intent": "bright bone", "settings": dict(SETTINGS),
            "judge": {"spec": url, "options": {"max_retries": 0, "answer_retries": 0,
                                               "timeout": 5, "deadline": 10}}}  # fmt: skip


def test_matches_without_an_answer_are_undecided_and_the_run_finishes(vol, tmp_path):
    target = np.full((40, 40, 3), 220, np.uint8)
    # A match is undecided when both of its orders fail (0.3² = 9 %: about 3.6 of 40; at 0.2,
    # 4 %, a change of the pictures once left none undecided). Seeds 5-9 all leave some.
    with FakeMLLMServer(target=target, faults={"server_error": 0.3}, seed=5) as srv:
        with Session.open(_spec(srv.base_url), tmp_path / "run", volume=vol) as s:
            out = s.run(write_outputs=False)
            failed = srv.stats.faults.get("server_error", 0)
    assert out.reason == "completed", out.message
    assert failed > 0
    undecided = sum(rec.match_stats["undecided"] for rec in s.records)
    assert 0 < undecided <= failed
    errors = [m["verdict"]["error"] for rec in _journal(tmp_path / "run")
              for m in rec.get("matches", []) if m["verdict"].get("error")]  # fmt: skip
    assert any("no answer" in e and "HTTP 500" in e for e in errors)


def test_a_judge_that_is_down_ends_the_run_and_says_so(vol, tmp_path):
    with socket.socket() as sock:  # a port nothing listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    with Session.open(_spec(f"http://127.0.0.1:{port}/v1"), tmp_path / "run", volume=vol) as s:
        out = s.run(write_outputs=False)
    assert out.reason == "judge"
    assert "judge is down" in out.message and "round 2" in out.message
    assert out.generations_done == 0


def _journal(run):
    import json

    return [json.loads(line) for line in (run / "journal.jsonl").read_text().splitlines()]
