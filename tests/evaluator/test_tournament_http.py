"""Judge, verdict cache, tournament and fake server together over real loopback HTTP.

Every fault kind the fake server can inject is on at once: the tournament still finishes,
ranks well, and keeps every paid verdict (a replay of the same tournament costs nothing).
"""

from __future__ import annotations

import asyncio
import sqlite3

import numpy as np
import pytest
from scipy.stats import kendalltau

from intuitf.errors import BudgetExhausted
from intuitf.evaluator.budget import Budget
from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.tournament import SwissTournament
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FAULT_KINDS, FakeMLLMServer


def _field(oracle_images, n=12):
    target, cands = oracle_images
    rng = np.random.default_rng(3)
    # More candidates than the fixture has: blends of neighbours keep the true order known.
    images, dist = [], []
    for k in range(n):
        t = k / (n - 1) * (len(cands) - 1)
        a, b = cands[int(np.floor(t))], cands[int(np.ceil(t))]
        f = t - np.floor(t)
        images.append(np.clip((1 - f) * a + f * b + 0.5, 0, 255).astype(np.uint8))
        dist.append(t)
    order = rng.permutation(n)
    return (
        target,
        [images[i] for i in order],
        [f"c{i:02d}" for i in range(n)],
        [dist[i] for i in order],
    )


def _judge(srv, cache, **kw):
    return MLLMJudge(
        "default", base_url=srv.base_url, cache=cache, swap="never", timeout=0.5,
        max_retries=6, backoff_base=0.01, backoff_max=0.05, **kw,
    )  # fmt: skip


@pytest.mark.slow
def test_tournament_survives_every_fault_kind_and_keeps_paid_verdicts(oracle_images, tmp_path):
    target, images, ids, dist = _field(oracle_images, n=16)
    faults = {k: 0.06 for k in FAULT_KINDS}
    cache_path = tmp_path / "verdicts.sqlite"
    with FakeMLLMServer(
        target=target, faults=faults, retry_after=0.01, hang_seconds=3, seed=9
    ) as srv:
        judge = _judge(srv, VerdictCache(cache_path))
        t = SwissTournament(
            judge, aspects_for("image"), Intent(kind="image", reference=target), seed=5
        )
        result = asyncio.run(t.run(images, ids))
        assert result.complete and len(result.ranking) == len(ids)
        assert len(srv.stats.faults) >= 5, srv.stats.faults  # most kinds were really injected
        truth = {i: d for i, d in zip(ids, dist, strict=True)}
        tau = kendalltau([truth[i] for i in result.ranking], range(len(ids))).statistic
        assert tau > 0.5, tau
        paid = judge.cost.calls
        assert paid > 0

        # Every real answer paid for is stored (refusals and unreadable answers are not).
        with sqlite3.connect(cache_path) as db:
            stored = db.execute("SELECT COUNT(*) FROM answers").fetchone()[0]
        answered = [m for m in result.matches if not m.verdict.error]
        assert stored == len(answered)

        # A replay with a new judge on the same file gets the first round (same seed, same
        # pairs) entirely from the cache, apart from questions that had no real answer.
        again = _judge(srv, VerdictCache(cache_path))
        replay = asyncio.run(
            SwissTournament(
                again, aspects_for("image"), Intent(kind="image", reference=target), seed=5
            ).run(images, ids)
        )
        first = {(m.first, m.second): m for m in result.matches if m.round == 1}
        for m in replay.matches:
            if m.round == 1 and not first[(m.first, m.second)].verdict.error:
                assert m.verdict.cached, (m.first, m.second)
                assert m.verdict.overall == first[(m.first, m.second)].verdict.overall


def test_budget_stops_the_tournament_and_keeps_what_was_paid(oracle_images, tmp_path):
    target, images, ids, _ = _field(oracle_images)
    cache = VerdictCache(tmp_path / "v.sqlite")
    with FakeMLLMServer(target=target, seed=1) as srv:
        judge = _judge(srv, cache, budget=Budget(max_calls=15))
        t = SwissTournament(
            judge, aspects_for("image"), Intent(kind="image", reference=target), seed=2
        )
        with pytest.raises(BudgetExhausted) as info:
            asyncio.run(t.run(images, ids))
        partial = info.value.partial
        assert 0 < len(partial.matches) <= 15
        assert judge.cost.calls == 15
        # Every one of the 15 paid answers is in the cache, none is asked again.
        before = srv.stats.requests
        replay_judge = _judge(srv, VerdictCache(tmp_path / "v.sqlite"), budget=Budget(max_calls=15))
        with pytest.raises(BudgetExhausted):
            asyncio.run(
                SwissTournament(
                    replay_judge,
                    aspects_for("image"),
                    Intent(kind="image", reference=target),
                    seed=2,
                ).run(images, ids)
            )
        assert replay_judge.cost.cached_calls >= 15
        assert replay_judge.cost.calls == 15  # the budget bought 15 new answers, not old ones
        assert srv.stats.requests - before == 15
