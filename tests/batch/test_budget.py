"""One budget for the whole batch: the ledger's atomic reservations, across threads, processes
and model judges, and requests of a killed process counted as spent."""

from __future__ import annotations

import asyncio
import multiprocessing as mp

import numpy as np
import pytest

from intuitf.batch.budget import BatchLedger, SharedBudget, attach_shared_budget
from intuitf.errors import BudgetExhausted
from intuitf.evaluator.budget import Budget
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.pricing import PriceTable
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer


def _grab(path: str, tries: int, out) -> None:
    ledger = BatchLedger(path)
    got = 0
    for _ in range(tries):
        row, _why = ledger.try_reserve("w", "v", 0.01)
        if row is not None:
            got += 1
            ledger.settle(row, 0.01)
    out.put(got)


def test_workers_in_several_processes_never_pass_the_limit(tmp_path):
    path = str(tmp_path / "budget.sqlite")
    ledger = BatchLedger(path)
    ledger.set_limits(57, None)
    ctx = mp.get_context("spawn")
    out = ctx.Queue()
    procs = [ctx.Process(target=_grab, args=(path, 40, out)) for _ in range(4)]
    for p in procs:
        p.start()
    got = [out.get(timeout=120) for _ in procs]
    for p in procs:
        p.join(30)
    assert sum(got) == 57  # exactly the limit: nobody took the last call twice
    t = ledger.totals()
    assert (t.paid_calls, t.in_flight, t.exhausted) == (57, 0, True)
    assert t.paid_usd == pytest.approx(0.57)


def test_money_limit_counts_calls_under_way_and_a_dead_process_requests(tmp_path):
    ledger = BatchLedger(tmp_path / "budget.sqlite")
    ledger.set_limits(None, 1.0)
    rows = [ledger.try_reserve("a", "v", 0.3)[0] for _ in range(3)]
    assert all(r is not None for r in rows)
    row, why = ledger.try_reserve("a", "v", 0.3)  # 0.9 under way + 0.3 > 1.0
    assert row is None and "money budget" in why
    ledger.release(rows[0])  # no answer: nothing paid, room again
    ledger.settle(rows[1], 0.5)  # dearer than expected
    assert ledger.totals().paid_usd == pytest.approx(0.5)
    # The process holding rows[2] dies; the next batch marks its request lost but counts it.
    again = BatchLedger(tmp_path / "budget.sqlite")
    assert again.mark_lost() == 1
    t = again.totals()
    assert (t.paid_calls, t.in_flight, t.lost) == (1, 0, 1)
    assert again.try_reserve("b", "v", 0.3)[0] is None  # 0.5 paid + 0.3 lost + 0.3 > 1.0


def test_shared_budget_keeps_the_run_budget_and_stops_at_the_batch_limit(tmp_path):
    ledger = BatchLedger(tmp_path / "budget.sqlite")
    ledger.set_limits(5, None)
    local = Budget(max_calls=3)
    local.restore(type("C", (), {"calls": 1, "usd": 0.0})())  # the run paid one call before
    b = SharedBudget(ledger, "vol", local)
    assert (b.max_calls, b.calls) == (3, 1)
    b.settle(b.reserve(0.0), 0.0)
    b.settle(b.reserve(0.0), 0.0)
    with pytest.raises(BudgetExhausted, match="call budget of 3"):  # the run's own limit
        b.reserve(0.0)
    other = SharedBudget(ledger, "other")
    reserved = [other.reserve(0.0) for _ in range(3)]
    with pytest.raises(BudgetExhausted, match="batch's call budget of 5"):
        other.reserve(0.0)
    assert other.under_way == 3
    for r in reserved:
        other.release(r)
    assert ledger.totals().calls == 2 and other.under_way == 0


def _images(n: int) -> list[np.ndarray]:
    rng = np.random.default_rng(0)
    return [rng.integers(0, 255, (32, 32, 3), dtype=np.uint8) for _ in range(n)]


def test_model_judges_of_several_runs_share_one_limit(tmp_path):
    """Two runs' judges ask concurrently; the server never sees more than the batch allows."""
    imgs = _images(24)
    ledger = BatchLedger(tmp_path / "budget.sqlite")
    ledger.set_limits(9, None)
    q = aspects_for("quality")
    prices = PriceTable().with_prices({"default": (100.0, 400.0)})
    with FakeMLLMServer(target=imgs[0], latency=0.05) as srv:
        judges = [
            MLLMJudge("default", base_url=srv.base_url, swap="never", prices=prices)
            for _ in range(2)
        ]
        for k, j in enumerate(judges):
            assert attach_shared_budget(j, ledger, f"run{k}") is j.budget

        async def ask(j, a, b):
            try:
                await j.compare(imgs[a], imgs[b], q, Intent())
                return "ok"
            except BudgetExhausted:
                return "budget"

        async def main():
            calls = [ask(judges[i % 2], i, i + 1) for i in range(20)]
            return await asyncio.gather(*calls)

        outcome = asyncio.run(main())
        requests = srv.stats.requests
    assert outcome.count("ok") == 9 == requests
    t = ledger.totals()
    assert (t.paid_calls, t.in_flight) == (9, 0) and t.paid_usd > 0
    assert sum(ledger.per_volume().values()) == 9


def test_a_workers_limiter_holds_requests_in_flight_and_per_second():
    from intuitf.batch.runner import JudgeLimiter, ThrottledJudge

    imgs = _images(10)
    q = aspects_for("quality")
    with FakeMLLMServer(target=imgs[0], latency=0.1) as srv:
        limiter = JudgeLimiter(max_in_flight=2, rate_per_s=20.0)
        judges = [
            ThrottledJudge(MLLMJudge("default", base_url=srv.base_url, swap="never"), limiter)
            for _ in range(2)
        ]

        async def main():
            t0 = asyncio.get_running_loop().time()
            await asyncio.gather(
                *(judges[i % 2].compare(imgs[i], imgs[i + 1], q, Intent()) for i in range(8))
            )
            return asyncio.get_running_loop().time() - t0

        elapsed = asyncio.run(main())
        assert srv.stats.requests == 8
        assert srv.stats.max_in_flight <= 2  # both runs' judges share the worker's limit
    assert elapsed >= 7 / 20.0 and elapsed >= 4 * 0.1
