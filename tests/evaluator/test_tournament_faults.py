"""A match the judge cannot answer is undecided, not the end of the tournament; a judge that is
down (most of a round unanswered) stops it with a message that says so."""

from __future__ import annotations

import asyncio
from collections import Counter

import numpy as np
import pytest

from intuitf.errors import JudgeError
from intuitf.evaluator.tournament import SwissTournament, TournamentResult
from intuitf.evaluator.types import Aspect, Choice, Cost, Verdict

ASPECTS = [Aspect("quality", "Quality", "overall quality")]


class FlakyJudge:
    """Prefers the brighter image; raises JudgeError on the calls whose number is in ``fail``."""

    name = "flaky"

    def __init__(self, fail=(), fail_from: int | None = None) -> None:
        self.fail = set(fail)
        self.fail_from = fail_from
        self.calls = 0

    async def compare(self, first, second, aspects, intent) -> Verdict:
        self.calls += 1
        n = self.calls
        await asyncio.sleep(0)
        if n in self.fail or (self.fail_from is not None and n >= self.fail_from):
            raise JudgeError(f"The model server gave no answer after 5 attempts (call {n}).")
        choice = Choice.FIRST if first.mean() > second.mean() else Choice.SECOND
        return Verdict({"quality": choice}, choice, choice.score, cost=Cost(calls=1))


def _play(judge, n=16, protocol="paper", **kw) -> TournamentResult:
    images = [np.full((4, 4, 3), 10 + 10 * i, np.uint8) for i in range(n)]
    ids = [f"c{i}" for i in range(n)]
    t = SwissTournament(judge, ASPECTS, seed=3, recheck_above=None, protocol=protocol, **kw)
    return asyncio.run(t.run(images, ids))


def test_a_match_without_an_answer_is_undecided_and_play_goes_on():
    judge = FlakyJudge(fail={3, 12})  # one match in round 1, one in round 2
    result = _play(judge)
    assert result.complete
    assert len(result.matches) == 8 * result.rounds  # every scheduled match is recorded
    undecided = [m for m in result.matches if not m.verdict.decided]
    assert len(undecided) == 2
    for m in undecided:
        assert m.verdict.overall is Choice.TIE and m.verdict.p_first == 0.5
        assert "no answer" in m.verdict.error and "5 attempts" in m.verdict.error
    stats = result.match_stats()
    assert (stats.undecided, stats.decided) == (2, 8 * result.rounds - 2)
    # The ranking still follows the brightness the judge answered on.
    assert result.ranking[0] == "c15"


def test_a_judge_that_is_down_stops_the_tournament_and_says_so():
    judge = FlakyJudge(fail_from=10)  # round 2 on: nothing answers
    with pytest.raises(JudgeError) as info:
        _play(judge)
    err = info.value
    assert "judge is down" in err.message
    assert "round 3" in err.message and "8 of 8 requests" in err.message
    partial = err.partial
    assert not partial.complete
    # Round 1, and round 2 (one answer, seven undecided) are kept; the unanswered matches of
    # round 3 are not recorded. Undecided matches are asked again by a resumed run.
    assert Counter(m.round for m in partial.matches) == {1: 8, 2: 8}
    assert Counter(m.verdict.decided for m in partial.matches) == {True: 9, False: 7}
    assert judge.calls == 24  # it stopped there


def test_one_bad_round_is_bad_luck_not_a_judge_that_is_down():
    # Most of round 1 fails (6 of 8), the rest of the tournament answers: it completes.
    result = _play(FlakyJudge(fail={1, 2, 3, 4, 5, 6}))
    assert result.complete and result.match_stats().undecided == 6
    # Most of every other round failing never makes two rounds in a row.
    result = _play(FlakyJudge(fail={*range(1, 7), *range(17, 23)}))
    assert result.complete and result.match_stats().undecided == 12


def test_the_efficient_protocol_asks_an_undecided_match_again_in_the_other_order():
    judge = FlakyJudge(fail={3, 12})
    result = _play(judge, protocol="efficient")
    assert result.complete
    assert judge.calls == 8 * result.rounds + 2  # one more ask per undecided match
    assert result.match_stats().undecided == 0
    again = [m for m in result.matches if m.rechecked]
    assert len(again) == 2 and all(m.verdict.decided for m in again)
    # The second answer stands alone (the brighter image wins), not averaged with a tie.
    for m in again:
        brighter_first = int(m.first[1:]) > int(m.second[1:])
        assert m.verdict.p_first == (1.0 if brighter_first else 0.0)
