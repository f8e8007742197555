"""MLLMJudge survives every fault the fake server injects, and stops cleanly on a dead server."""

from __future__ import annotations

import asyncio
import logging
import socket
import time

import pytest

from intuitf.errors import JudgeError
from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.types import Choice, Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer

Q = aspects_for("quality")
PAIRS = [(0, 3), (4, 1), (2, 5), (6, 0), (1, 7), (5, 2), (3, 6), (7, 4)]


def _fast(srv, **kw):
    kw.setdefault("swap", "never")
    kw.setdefault("max_retries", 8)
    return MLLMJudge("default", base_url=srv.base_url, backoff_base=0.001, backoff_max=0.01, **kw)


async def _all(judge, c, pairs=PAIRS):
    return await asyncio.gather(*(judge.compare(c[i], c[j], Q, Intent()) for i, j in pairs))


@pytest.mark.parametrize("kind", ["server_error", "overloaded", "rate_limit"])
def test_transient_http_errors_are_retried(oracle_images, kind):
    target, c = oracle_images
    with FakeMLLMServer(target=target, faults={kind: 0.5}, retry_after=0.01, seed=2) as srv:
        judge = _fast(srv)
        verdicts = asyncio.run(_all(judge, c))
    assert srv.stats.faults[kind] >= 2
    for (i, j), v in zip(PAIRS, verdicts, strict=True):
        assert v.overall is (Choice.FIRST if i < j else Choice.SECOND) and v.error is None
    assert judge.cost.failed_calls == srv.stats.faults[kind]
    assert judge.cost.calls == len(PAIRS)


def test_retry_after_is_honoured(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, faults={"rate_limit": 0.5}, retry_after=0.08, seed=5) as srv:
        judge = _fast(srv)
        t0 = time.perf_counter()
        for i, j in PAIRS[:5]:  # one after another, so the waits add up
            assert asyncio.run(judge.compare(c[i], c[j], Q, Intent())).error is None
        elapsed = time.perf_counter() - t0
    n429 = srv.stats.faults.get("rate_limit", 0)
    assert n429 >= 2
    # Backoff alone would wait at most 0.01 s per retry; the server asked for 0.08 s.
    assert elapsed >= 0.08 * n429


def test_hang_times_out_and_is_retried(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, faults={"hang": 0.4}, hang_seconds=30, seed=4) as srv:
        judge = _fast(srv, timeout=0.3)
        t0 = time.perf_counter()
        verdicts = asyncio.run(_all(judge, c, PAIRS[:4]))
        elapsed = time.perf_counter() - t0
    assert srv.stats.faults["hang"] >= 1
    assert all(v.error is None for v in verdicts)
    assert elapsed < 10  # nowhere near the 30 s hang


@pytest.mark.parametrize("kind", ["refusal", "blind", "malformed", "truncated"])
def test_answers_unusable_every_time_become_logged_uncached_ties(oracle_images, kind, caplog):
    target, c = oracle_images
    cache = VerdictCache(":memory:")
    with FakeMLLMServer(target=target, faults={kind: 1.0}) as srv:
        judge = _fast(srv, cache=cache)
        with caplog.at_level(logging.WARNING, logger="intuitf.evaluator.mllm"):
            v = asyncio.run(judge.compare(c[0], c[5], Q, Intent()))
    assert v.overall is Choice.TIE and v.p_first == 0.5 and not v.decided
    reason = {"blind": "blind", "refusal": "refusal"}.get(kind, "unreadable")
    assert v.error and v.error.startswith(reason)
    assert set(v.per_aspect.values()) == {Choice.TIE}
    # Asked again before giving up: a refusal once more, anything else answer_retries times.
    asked = 2 if kind == "refusal" else 1 + judge.answer_retries
    assert v.retries == asked - 1
    assert v.cost.calls == asked == srv.stats.requests  # every answer was paid for, even useless
    assert len(cache) == 0  # and none is kept as a real answer
    assert "tie" in caplog.text


def test_one_good_order_outweighs_an_unusable_one(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, faults={"refusal": 0.5}, seed=11) as srv:
        judge = _fast(srv, swap="always")
        verdicts = asyncio.run(_all(judge, c))
    assert srv.stats.faults["refusal"] >= 2
    for (i, j), v in zip(PAIRS, verdicts, strict=True):
        assert v.overall in (Choice.FIRST if i < j else Choice.SECOND, Choice.TIE)
        assert (v.error is None) or v.overall is Choice.TIE
    assert sum(v.error is None for v in verdicts) > len(PAIRS) // 2


def test_erroring_server_raises_judge_error(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, faults={"server_error": 1.0}) as srv:
        judge = _fast(srv, max_retries=2)
        with pytest.raises(JudgeError) as exc:
            asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
    assert srv.stats.requests == 3
    assert "no answer after 3 attempts" in exc.value.message and "HTTP 500" in exc.value.message
    assert "resume" in exc.value.hint
    assert judge.cost.failed_calls == 3 and judge.cost.calls == 0


def test_unreachable_server_raises_judge_error(oracle_images):
    _, c = oracle_images
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    judge = MLLMJudge(
        "default", base_url=f"http://127.0.0.1:{port}/v1", max_retries=1, backoff_base=0.001
    )
    with pytest.raises(JudgeError, match="connection failed"):
        asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
