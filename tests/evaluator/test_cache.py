"""The verdict cache: repeated questions are free, paid answers survive new judges and crashes."""

from __future__ import annotations

import asyncio
import sqlite3

import numpy as np

from intuitf.evaluator.cache import VerdictCache, request_key
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.types import Choice, Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer

Q = aspects_for("quality")


def test_request_key_depends_on_every_piece():
    a = np.zeros((4, 4, 3), np.uint8)
    b = a.copy()
    b[0, 0, 0] = 1
    base = request_key("j", ["p", a])
    assert base == request_key("j", ["p", a.copy()])
    assert base != request_key("k", ["p", a])
    assert base != request_key("j", ["q", a])
    assert base != request_key("j", ["p", b])
    assert request_key("j", ["ab", "c"]) != request_key("j", ["a", "bc"])


def test_store_and_reopen(tmp_path):
    path = tmp_path / "sub" / "verdicts.sqlite"
    with VerdictCache(path) as cache:
        cache.put("k1", "judge", {"per_aspect": {"x": "first"}})
        assert cache.get("k1") == {"per_aspect": {"x": "first"}} and cache.get("k2") is None
        assert (cache.hits, cache.misses) == (1, 1)
    # Committed at once: another connection sees it, in WAL mode.
    with sqlite3.connect(path) as db:
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert db.execute("SELECT COUNT(*) FROM answers").fetchone()[0] == 1
    assert len(VerdictCache(path)) == 1


def test_repeated_question_costs_nothing_and_survives_a_new_judge(oracle_images, tmp_path):
    target, c = oracle_images
    path = tmp_path / "v.sqlite"
    with FakeMLLMServer(target=target) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never", cache=VerdictCache(path))
        v1 = asyncio.run(judge.compare(c[0], c[4], Q, Intent()))
        v2 = asyncio.run(judge.compare(c[0], c[4], Q, Intent()))
        assert srv.stats.requests == 1
        assert not v1.cached and v1.cost.calls == 1
        assert v2.cached and v2.cost.calls == 0 and v2.cost.cached_calls == 1
        assert v2.cost.usd == 0 and v2.cost.input_tokens == 0
        assert v2.per_aspect == v1.per_aspect and v2.overall is Choice.FIRST

        # A new judge and a new connection to the same file: still nothing to pay.
        again = MLLMJudge("default", base_url=srv.base_url, swap="always", cache=VerdictCache(path))
        v3 = asyncio.run(again.compare(c[4], c[0], Q, Intent()))
        # The order (4, 0) of "always" is the question already asked (0, 4) swapped: one new call.
        assert srv.stats.requests == 2
        assert v3.overall is Choice.SECOND and v3.cost.cached_calls == 1 and v3.cost.calls == 1
        v4 = asyncio.run(again.compare(c[0], c[4], Q, Intent()))
        assert v4.cached and srv.stats.requests == 2
        assert again.cost.cached_calls == 3 and again.cost.calls == 1


def test_the_key_covers_intent_and_aspects(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never", cache=VerdictCache())
        asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
        asyncio.run(judge.compare(c[0], c[1], Q, Intent(about="a phantom")))
        asyncio.run(judge.compare(c[0], c[1], aspects_for("text"), Intent(kind="text", text="x")))
        asyncio.run(judge.compare(c[0], c[1], aspects_for("text"), Intent(kind="text", text="y")))
        asyncio.run(judge.compare(c[0], c[2], Q, Intent()))
        assert srv.stats.requests == 5
        asyncio.run(judge.compare(c[0], c[1], Q, Intent(about="a phantom")))
        assert srv.stats.requests == 5


def test_concurrent_tasks_share_one_cache(oracle_images, tmp_path):
    target, c = oracle_images
    cache = VerdictCache(tmp_path / "c.sqlite")
    pairs = [(i, j) for i in range(6) for j in range(6) if i != j]

    async def run(judge):
        return await asyncio.gather(*(judge.compare(c[i], c[j], Q, Intent()) for i, j in pairs))

    with FakeMLLMServer(target=target, latency=0.01) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never", cache=cache)
        asyncio.run(run(judge))
        assert len(cache) == len(pairs) == srv.stats.requests
        again = asyncio.run(run(judge))
        assert all(v.cached for v in again) and srv.stats.requests == len(pairs)
