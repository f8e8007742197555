"""A generation whose candidates the judge cannot tell apart says so."""

from __future__ import annotations

from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.types import Choice, Cost, Intent, Verdict
from intuitf.session import RunSettings, Session
from intuitf.volume.phantom import phantom

SMALL = dict(population=4, generations=1, image_size=32, output_size=32, top_k=1)


class TieJudge:
    """A judge that finds every pair alike."""

    name = "tie"

    async def compare(self, first, second, aspects, intent) -> Verdict:
        return Verdict({a.key: Choice.TIE for a in aspects}, Choice.TIE, 0.5, cost=Cost(calls=1))


def test_a_generation_of_ties_is_indistinct(tmp_path):
    with Session.create(phantom(24), intent=Intent(kind="text", text="red bone"),
                        judge=TieJudge(), settings=RunSettings(**SMALL)) as s:  # fmt: skip
        rec = s.step()
    assert rec.match_stats["decided"] > 0
    assert rec.match_stats["ties"] == rec.match_stats["decided"]
    assert rec.match_stats["indistinct"] == 1


def test_a_judge_that_tells_them_apart_is_not(tmp_path):
    with Session.create(phantom(24), intent=Intent(kind="text", text="red bone"),
                        judge=MetricJudge(), settings=RunSettings(**SMALL)) as s:  # fmt: skip
        rec = s.step()
    assert rec.match_stats["indistinct"] == 0
