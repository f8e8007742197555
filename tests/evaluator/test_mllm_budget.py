"""Cost accounting (usage × price) and budgets that stop before the call that would overspend."""

from __future__ import annotations

import asyncio

import pytest

from intuitf.errors import BudgetExhausted
from intuitf.evaluator.budget import Budget
from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.pricing import PriceTable
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer

Q = aspects_for("quality")
PRICES = PriceTable().with_prices({"default": (100.0, 400.0)})  # USD per 1M tokens


def test_cost_is_usage_times_price(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, prices=PRICES)
        verdicts = [asyncio.run(judge.compare(c[i], c[i + 1], Q, Intent())) for i in range(3)]
    st = srv.stats
    assert judge.cost.calls == 6 == st.answered
    assert judge.cost.input_tokens == st.input_tokens > 0
    assert judge.cost.output_tokens == st.output_tokens > 0
    want = (st.input_tokens * 100.0 + st.output_tokens * 400.0) / 1e6
    assert judge.cost.usd == pytest.approx(want, rel=1e-12)
    assert sum(v.cost.usd for v in verdicts) == pytest.approx(want, rel=1e-12)


def test_price_table_lookup():
    t = PriceTable()
    assert t.cost("gpt-4o", 1_000_000, 0) == pytest.approx(2.5)
    assert t.lookup("gpt-4o-2024-08-06") == t.lookup("gpt-4o")
    assert t.lookup("gpt-4o-mini-2024-07-18") == t.lookup("gpt-4o-mini") != t.lookup("gpt-4o")
    assert t.lookup("openai/gpt-4o") == t.lookup("gpt-4o")
    assert t.cost("my-local-model", 10**6, 10**6) == 0.0
    with pytest.raises(ValueError):
        t.with_prices({"x": (-1, 0)})


def test_call_budget_stops_before_the_call_and_keeps_paid_verdicts(oracle_images):
    target, c = oracle_images
    cache = VerdictCache(":memory:")
    budget = Budget(max_calls=3)
    with FakeMLLMServer(target=target) as srv:
        judge = MLLMJudge(
            "default", base_url=srv.base_url, swap="never", cache=cache, budget=budget
        )
        for i in range(3):
            asyncio.run(judge.compare(c[i], c[i + 1], Q, Intent()))
        with pytest.raises(BudgetExhausted) as exc:
            asyncio.run(judge.compare(c[5], c[6], Q, Intent()))
        assert srv.stats.requests == 3 and budget.calls == 3 and len(cache) == 3
        assert "kept" in exc.value.hint
        # What was paid for is still free to ask again.
        v = asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
        assert v.cached and srv.stats.requests == 3


def test_concurrent_calls_cannot_overshoot_the_call_budget(oracle_images):
    target, c = oracle_images
    budget = Budget(max_calls=5)
    cache = VerdictCache(":memory:")

    async def many(judge):
        return await asyncio.gather(
            *(judge.compare(c[i], c[j], Q, Intent()) for i in range(4) for j in range(4) if i != j),
            return_exceptions=True,
        )

    with FakeMLLMServer(target=target, latency=0.02) as srv:
        judge = MLLMJudge(
            "default", base_url=srv.base_url, swap="never", cache=cache, budget=budget
        )
        out = asyncio.run(many(judge))
    assert srv.stats.requests == 5 == budget.calls == len(cache)
    assert sum(isinstance(r, BudgetExhausted) for r in out) == 12 - 5


def test_money_budget(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never", prices=PRICES)
        # Before its first answer a judge guesses high (image tokens of big cloud models) ...
        with pytest.raises(BudgetExhausted):
            judge.budget = Budget(max_usd=1e-9)
            asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
        judge.budget = None
        asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
        per_call = judge.cost.usd
        # ... and then estimates from the dearest call it has seen.
        judge.budget = budget = Budget(max_usd=2.5 * per_call)
        asyncio.run(judge.compare(c[1], c[2], Q, Intent()))
        asyncio.run(judge.compare(c[2], c[3], Q, Intent()))
        with pytest.raises(BudgetExhausted, match="money budget"):
            asyncio.run(judge.compare(c[3], c[4], Q, Intent()))
    assert budget.calls == 2 and budget.usd <= budget.max_usd
    assert srv.stats.requests == 3


def test_a_send_gate_stops_queued_requests_unsent_and_frees_their_budget(oracle_images):
    """A batch worker whose driver died: comparisons already waiting for a turn are not sent."""
    from intuitf.errors import RunCancelled

    target, c = oracle_images
    budget = Budget(max_calls=100)
    gone = {"now": False}

    def gate() -> None:
        if gone["now"]:
            raise RunCancelled("the driver is gone")

    with FakeMLLMServer(target=target, latency=0.3) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never", budget=budget,
                          max_concurrency=1)  # fmt: skip
        judge.add_send_gate(gate)

        async def scenario():
            first = asyncio.create_task(judge.compare(c[0], c[1], Q, Intent()))
            queued = [asyncio.create_task(judge.compare(c[i], c[i + 1], Q, Intent()))
                      for i in range(1, 4)]  # fmt: skip
            while srv.stats.in_flight == 0:
                await asyncio.sleep(0.01)
            gone["now"] = True  # while the first is on the server and three wait their turn
            done = await asyncio.gather(first, *queued, return_exceptions=True)
            return done

        done = asyncio.run(scenario())
    # The one sent is answered and kept, the three waiting are stopped. Which of the four
    # takes the single slot first is asyncio's choice, not the order the tasks were made in.
    sent = [d for d in done if not isinstance(d, BaseException)]
    assert len(sent) == 1
    assert sum(isinstance(d, RunCancelled) for d in done) == 3
    assert srv.stats.requests == 1
    assert budget.calls == 1 and budget.remaining_calls == 99
    assert budget._reserved_calls == 0  # nothing left reserved by the stopped requests
