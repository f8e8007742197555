"""An unusable answer is asked again, not turned into a tie (issue 8, item 3).

Unreadable and truncated answers get a corrective follow-up, a refusal one more try, a "blind"
answer is sent again; a verdict says how many re-asks it took and whether it was decided, and a
tournament counts decided, undecided and re-asked matches.
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.tournament import MatchRecord, MatchStats, SwissTournament
from intuitf.evaluator.types import Choice, Intent, Verdict
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FAULT_KINDS, FakeMLLMServer

Q = aspects_for("quality")
PAIRS = [(0, 3), (4, 1), (2, 5), (6, 0), (1, 7), (5, 2), (3, 6), (7, 4)]


def _judge(srv, **kw):
    kw.setdefault("swap", "never")
    return MLLMJudge(
        "default",
        base_url=srv.base_url,
        backoff_base=0.001,
        backoff_max=0.01,
        timeout=kw.pop("timeout", 2.0),
        **kw,
    )


@pytest.mark.parametrize("kind", ["malformed", "truncated", "refusal", "blind"])
def test_an_unusable_answer_is_asked_again_and_decides(oracle_images, kind):
    target, c = oracle_images
    cache = VerdictCache(":memory:")
    with FakeMLLMServer(target=target, faults={kind: 0.3}, seed=3) as srv:
        judge = _judge(srv, cache=cache)

        async def all_pairs():
            return await asyncio.gather(*(judge.compare(c[i], c[j], Q, Intent()) for i, j in PAIRS))

        verdicts = asyncio.run(all_pairs())
        asked, follow_ups = srv.stats.requests, srv.stats.follow_ups
        # The usable answers are cached under the original questions: a replay costs nothing.
        replay = asyncio.run(all_pairs())
        assert srv.stats.requests - asked <= (1 + judge.answer_retries) * sum(
            not v.decided for v in verdicts
        )
        assert all(r.cached for r, v in zip(replay, verdicts, strict=True) if v.decided)
    assert srv.stats.faults[kind] >= 2
    retried = [v for v in verdicts if v.retries]
    assert retried, "no answer was asked again"
    # Asked again, the model answered: the right choice, not a tie.
    for (i, j), v in zip(PAIRS, verdicts, strict=True):
        if v.decided:
            assert v.overall is (Choice.FIRST if i < j else Choice.SECOND)
    assert sum(v.decided for v in verdicts) >= len(PAIRS) - 2
    # Every request was paid for, the unusable ones too, and the verdicts' costs say so.
    assert sum(v.cost.calls for v in verdicts) == asked
    assert sum(v.retries for v in verdicts) == asked - len(PAIRS)
    if kind in ("malformed", "truncated", "refusal"):
        # ... with a follow-up that carries the bad answer and says how to answer.
        assert follow_ups == asked - len(PAIRS)
    else:  # "blind": the images may not have arrived; the question is sent again as it was
        assert follow_ups == 0


def test_a_refusal_is_asked_once_more_then_counted_as_a_tie(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, faults={"refusal": 1.0}) as srv:
        judge = _judge(srv, answer_retries=5)
        v = asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
    assert srv.stats.requests == 2 and v.retries == 1
    assert not v.decided and v.error.startswith("refusal") and v.p_first == 0.5


def test_no_reasks_when_answer_retries_is_zero(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, faults={"malformed": 1.0}) as srv:
        judge = _judge(srv, answer_retries=0)
        v = asyncio.run(judge.compare(c[0], c[1], Q, Intent()))
    assert srv.stats.requests == 1 and v.retries == 0 and not v.decided


def test_verdict_round_trips_retries():
    v = Verdict({"a": Choice.FIRST}, Choice.FIRST, 1.0, retries=2)
    back = Verdict.from_dict(v.to_dict())
    assert back.retries == 2 and back.decided
    assert v.swapped().retries == 2
    assert Verdict.from_dict({**v.to_dict(), "retries": None}).retries == 0  # older journals


def test_match_stats_count_and_warn():
    def match(error=None, retries=0):
        v = Verdict({"a": Choice.TIE}, Choice.TIE, 0.5, error=error, retries=retries)
        return MatchRecord(1, "x", "y", v)

    matches = [match() for _ in range(17)] + [match(retries=1), match("refusal", 1), match()]
    stats = MatchStats.of(matches)
    assert (stats.matches, stats.decided, stats.undecided, stats.retried) == (20, 19, 1, 2)
    assert stats.warning is None  # 5 %: at the limit, not above
    stats += MatchStats.of([match("unreadable: x", 2)])
    assert stats.undecided == 2 and stats.warning and "2 of 21" in stats.warning
    # From journal entries: their counts, or their matches for journals written before.
    entries = [
        {"type": "generation", "decided": 9, "undecided": 1, "retried": 3},
        {"type": "generation", "matches": [m.to_dict() for m in matches]},
    ]
    total = MatchStats.from_journal(entries)
    assert (total.matches, total.undecided, total.retried) == (30, 2, 5)


def _field(target, cands, n):
    """``n`` images whose true order is known: blends of the fixture's neighbours."""
    images, dist = [], []
    for k in range(n):
        t = k / (n - 1) * (len(cands) - 1)
        a, b = cands[int(np.floor(t))], cands[int(np.ceil(t))]
        f = t - np.floor(t)
        images.append(np.clip((1 - f) * a + f * b + 0.5, 0, 255).astype(np.uint8))
        dist.append(t)
    return images, [f"c{i:02d}" for i in range(n)]


@pytest.mark.slow
def test_fault_storm_leaves_at_most_5_percent_of_matches_undecided(oracle_images):
    """5 % of every fault kind at once (40 % of requests go wrong in some way)."""
    target, cands = oracle_images
    images, ids = _field(target, cands, 32)
    faults = {k: 0.05 for k in FAULT_KINDS}
    with FakeMLLMServer(
        target=target, faults=faults, retry_after=0.01, hang_seconds=5, seed=21
    ) as srv:
        judge = _judge(srv, timeout=0.5, deadline=10, max_retries=6)
        t = SwissTournament(judge, Q, Intent(), seed=4)
        result = asyncio.run(t.run(images, ids))
    assert result.complete
    assert set(srv.stats.faults) == set(FAULT_KINDS), srv.stats.faults
    stats = result.match_stats()
    assert stats.matches == len(result.matches) >= 100
    assert stats.retried > 0
    assert stats.undecided_share <= 0.05, stats
    assert stats.warning is None


def test_the_report_shows_decided_and_undecided_matches_and_warns(tmp_path):
    import json

    from intuitf.report import collect_run, report_html

    gens = [
        {"type": "generation", "generation": 0, "stage": "customize", "calls": 40,
         "decided": 36, "undecided": 4, "retried": 7, "candidates": [], "matches": []},
        {"type": "generation", "generation": 1, "stage": "customize", "calls": 40,
         "decided": 39, "undecided": 1, "retried": 2, "candidates": [], "matches": []},
    ]  # fmt: skip
    end = {"type": "end", "reason": "budget", "message": "spent", "cost": {"calls": 95}}
    (tmp_path / "run.json").write_text(json.dumps({"settings": {}}))
    (tmp_path / "journal.jsonl").write_text("".join(json.dumps(e) + "\n" for e in [*gens, end]))
    page = report_html(collect_run(tmp_path))
    assert "80: 75 decided, 5 undecided, 9 asked again" in page
    assert "Warning:" in page and "5 of 80 matches (6 %) stayed undecided" in page
    # The paid calls are the verdict store's (end entry): also the interrupted generation's.
    assert "<th>judge calls</th><td>95</td>" in page
    gens[0]["undecided"], gens[0]["decided"] = 0, 40
    (tmp_path / "journal.jsonl").write_text("".join(json.dumps(e) + "\n" for e in gens))
    assert "Warning:" not in report_html(collect_run(tmp_path))
