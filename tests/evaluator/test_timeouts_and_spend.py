"""A hanging server fails an answer within its deadline; spend is recorded per paid request;
budgets refuse negative limits; credentials in URLs never show (issue 8, items 1 and 4)."""

from __future__ import annotations

import asyncio
import logging
import time

import numpy as np
import pytest

from intuitf.errors import BudgetExhausted, IntuitfError, JudgeError
from intuitf.evaluator.budget import (
    Budget,
    reset_spend,
    restore_budget,
    run_spend,
    with_spend,
)
from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.factory import (
    judge_record,
    make_judge,
    record_judge_move,
    resume_judge_spec,
)
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.providers import (
    DEFAULT_ANSWER_DEADLINE,
    DEFAULT_REQUEST_TIMEOUT,
    redact_url,
)
from intuitf.evaluator.types import Cost, Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer

Q = aspects_for("quality")


@pytest.fixture(autouse=True)
def _no_user_config(tmp_path, monkeypatch):
    monkeypatch.setenv("INTUITF_CONFIG", str(tmp_path / "no-config.toml"))


# -- a hanging server ---------------------------------------------------------------------------


def test_a_hanging_server_fails_the_answer_within_its_deadline(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, faults={"hang": 1.0}, hang_seconds=60) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, timeout=0.3, deadline=1.0)
        t0 = time.perf_counter()
        with pytest.raises(JudgeError) as exc:
            asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
        first = time.perf_counter() - t0
        # For a while, other answers fail at once instead of waiting for the same dead server.
        t0 = time.perf_counter()
        with pytest.raises(JudgeError):
            asyncio.run(judge.compare(c[2], c[3], Q, Intent()))
        second = time.perf_counter() - t0
        asked = srv.stats.requests
    assert 0.9 <= first < 3.0, first
    assert second < 0.5 and asked <= 4
    assert "no answer within 1 s" in exc.value.message and "timed out" in exc.value.message
    assert "intuitf optimize --resume" in exc.value.hint
    assert "--request-timeout" in exc.value.hint


def test_default_timeouts_fail_a_dead_server_within_about_a_minute():
    judge = MLLMJudge("default", base_url="http://127.0.0.1:9/v1")
    assert judge.timeout == DEFAULT_REQUEST_TIMEOUT <= 30
    assert judge.deadline == DEFAULT_ANSWER_DEADLINE <= 60  # was 5 x 60 s = 5 min 11 s


def test_timeouts_come_from_the_config_file(tmp_path, monkeypatch):
    cfg = tmp_path / "config.toml"
    cfg.write_text("[judge]\nrequest_timeout = 7\nanswer_deadline = 12.5\n")
    monkeypatch.setenv("INTUITF_CONFIG", str(cfg))
    judge = make_judge("http://127.0.0.1:9/v1")
    assert (judge.timeout, judge.deadline) == (7.0, 12.5)
    judge = make_judge("http://127.0.0.1:9/v1", timeout=2, deadline=3)  # options win
    assert (judge.timeout, judge.deadline) == (2.0, 3.0)
    cfg.write_text('[judge]\nrequest_timeout = "soon"\n')
    with pytest.raises(JudgeError, match="request_timeout"):
        make_judge("http://127.0.0.1:9/v1")


def test_a_slow_answer_within_the_timeout_is_not_cut(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, latency=0.3) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never", timeout=2, deadline=3)
        v = asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
    assert v.decided and srv.stats.requests == 1


# -- spend --------------------------------------------------------------------------------------


def test_every_answered_request_is_recorded_as_spend(oracle_images, tmp_path):
    target, c = oracle_images
    path = tmp_path / "verdicts.sqlite"
    faults = {"malformed": 0.3, "server_error": 0.3}
    with FakeMLLMServer(target=target, faults=faults, seed=1) as srv:
        judge = MLLMJudge(
            "default", base_url=srv.base_url, cache=VerdictCache(path), swap="always",
            backoff_base=0.001, backoff_max=0.01, max_retries=8,
        )  # fmt: skip
        asyncio.run(judge.compare(c[0], c[4], Q, Intent()))
        asyncio.run(judge.compare(c[5], c[2], Q, Intent()))
    assert srv.stats.faults.get("malformed") and srv.stats.faults.get("server_error")
    spent = VerdictCache(path).spent()  # another connection: it was committed
    # Answered requests are paid, usable or not; a 500 is not an answer.
    assert spent.calls == srv.stats.answered == judge.cost.calls
    assert spent.input_tokens == srv.stats.input_tokens
    assert spent.output_tokens == srv.stats.output_tokens
    assert VerdictCache(path).unsettled() == (0, 0.0)


def test_requests_a_dead_process_left_under_way_count_as_unsettled(tmp_path):
    path = tmp_path / "v.sqlite"
    dead = VerdictCache(path)
    row = dead.begin_spend("j", 0.25)
    dead.begin_spend("j", 0.5)  # never settled: the process "died" with both under way
    dead.settle_spend(row, 10, 2, 0.2)
    alive = VerdictCache(path)
    assert alive.spent() == Cost(calls=1, input_tokens=10, output_tokens=2, usd=0.2)
    assert alive.unsettled() == (1, 0.5)
    assert dead.unsettled() == (0, 0.0)  # its own requests are merely in flight
    own = alive.begin_spend("j")
    alive.cancel_spend(own)  # no answer: nothing paid
    assert alive.spent().calls == 1
    alive.record_spend("j", 1, 1, 0.1)
    assert alive.spent().calls == 2
    alive.clear_spend()
    assert alive.spent() == Cost() and alive.unsettled() == (0, 0.0)


def test_a_resume_restores_the_budget_from_the_store(tmp_path):
    path = tmp_path / "verdicts.sqlite"
    store = VerdictCache(path)
    for _ in range(60):
        store.record_spend("url:default", 100, 10, 0.01)
    store.begin_spend("url:default", 0.01)  # under way when the process was killed

    class J:
        cache = VerdictCache(path)
        budget = Budget(max_calls=100)

    spent = restore_budget(J, path)
    assert spent.calls == 60
    assert J.budget.calls == 61  # the unsettled request may have been answered: it counts
    for _ in range(39):
        J.budget.settle(J.budget.reserve(), 0.01)
    with pytest.raises(BudgetExhausted, match="100 calls is spent"):
        J.budget.reserve()
    # The figures shown count what was paid and the request under way when the process died
    # (the provider may have charged it), like the budget above.
    assert run_spend(J, path).calls == 61
    assert run_spend(J, tmp_path / "another.sqlite") is None  # not this run's store
    cost = with_spend(Cost(calls=5, cached_calls=7, seconds=3.0), spent)
    assert (cost.calls, cost.cached_calls, cost.seconds, cost.input_tokens) == (60, 7, 3.0, 6000)
    # A new run in the folder (--overwrite): its spend and budget start from nothing.
    reset_spend(J, path)
    assert J.budget.calls == 0 and J.cache.spent() == Cost() and J.cache.unsettled()[0] == 0


@pytest.mark.parametrize("kw", [{"max_calls": -1}, {"max_usd": -0.5}, {"max_usd": float("nan")}])
def test_a_negative_budget_is_refused(kw):
    with pytest.raises(IntuitfError, match="cannot be negative"):
        Budget(**kw)


def test_budget_message_counts_calls_under_way():
    b = Budget(max_calls=3)
    r = [b.reserve() for _ in range(3)]
    b.settle(r[0], 0.0)
    with pytest.raises(BudgetExhausted) as exc:
        b.reserve()
    assert "3 calls is spent (1 paid, 2 more under way)" in exc.value.message


# -- credentials in URLs ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "url, shown",
    [
        ("http://user:KEY123@host/v1", "http://user:***@host/v1"),
        ("https://KEY123@host:8443/v1#model", "https://***@host:8443/v1#model"),
        ("https://host/v1?key=KEY123&x=1", "https://host/v1?key=***&x=1"),
        ("http://host:8000/v1", "http://host:8000/v1"),
        ("failed at http://u:KEY123@h/v1/ (HTTP 500)", "failed at http://u:***@h/v1/ (HTTP 500)"),
        (None, None),
    ],
)
def test_redact_url(url, shown):
    assert redact_url(url) == shown


def test_a_judge_never_shows_credentials_in_its_url(caplog):
    judge = make_judge("http://user:KEY123@127.0.0.1:9/v1#m", max_retries=0)
    assert "KEY123" not in repr(judge) and "KEY123" not in judge.base_url
    assert judge._url.reveal() == "http://user:KEY123@127.0.0.1:9/v1/"  # still used to connect
    img = np.zeros((8, 8, 3), np.uint8)
    with caplog.at_level(logging.DEBUG), pytest.raises(JudgeError) as exc:
        asyncio.run(judge.compare(img, img + 1, Q, Intent()))
    assert "KEY123" not in str(exc.value) and "user:***@" in str(exc.value)
    assert "KEY123" not in caplog.text


def test_judge_records_are_redacted_and_resume_may_move_the_run():
    rec = judge_record("http://u:KEY@old:1/v1#qwen", None)
    assert rec["evaluator"] == "http://u:***@old:1/v1#qwen"
    assert rec["judges"] == [
        {"evaluator": "http://u:***@old:1/v1#qwen", "base_url": None, "from_generation": 0}
    ]
    # The key was not stored, so resuming at the same address needs it given again.
    with pytest.raises(JudgeError, match="credentials"):
        resume_judge_spec(rec)
    # --base-url moves a URL-evaluator run to the new server, keeping its model.
    spec, url, moved = resume_judge_spec(rec, None, "http://new:2/v1")
    assert (spec, url, moved) == ("http://new:2/v1#qwen", None, True)
    entry = record_judge_move(rec, spec, url, 3)
    assert entry == {"evaluator": "http://new:2/v1#qwen", "base_url": None, "from_generation": 3}
    assert rec["evaluator"] == spec and len(rec["judges"]) == 2
    # Nothing new given: the run stays where it is.
    assert resume_judge_spec({"evaluator": "http://a:1/v1"}) == ("http://a:1/v1", None, False)
    # A new evaluator: another model (a provider's recorded address stays with that provider).
    old = {"evaluator": "vllm:a", "base_url": "http://gpu:8000/v1"}
    assert resume_judge_spec(old, "vllm:b") == ("vllm:b", "http://gpu:8000/v1", True)
    assert resume_judge_spec(old, "ollama:llava") == ("ollama:llava", None, True)
    assert resume_judge_spec(old, None, "http://gpu2:8000/v1")[1:] == ("http://gpu2:8000/v1", True)
