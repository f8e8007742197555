"""The in-process oracle judge answers by the fake server's rule."""

from __future__ import annotations

import asyncio

import numpy as np

from intuitf.evaluator.types import Aspect, Choice, Intent
from intuitf.testing import OracleJudge

ASPECTS = [Aspect("closeness", "Closeness", "closer to the target")]


def _img(v: int) -> np.ndarray:
    return np.full((8, 8, 3), v, np.uint8)


def _verdicts(judge, a, b, n):
    async def go():
        return [await judge.compare(_img(a), _img(b), ASPECTS, Intent()) for _ in range(n)]

    return asyncio.run(go())


def test_follows_the_score_and_counts_calls():
    judge = OracleJudge(lambda im: float(im.mean()))
    assert all(v.overall is Choice.SECOND and v.p_first == 0.0 for v in _verdicts(judge, 10, 20, 5))
    assert _verdicts(judge, 30, 30, 1)[0].overall is Choice.TIE
    assert judge.cost.calls == 6 and judge.score(_img(20)) == 20.0


def test_noise_and_position_bias_rates():
    noisy = OracleJudge(lambda im: float(im.mean()), noise=0.1, seed=1)
    wrong = np.mean([v.overall is Choice.FIRST for v in _verdicts(noisy, 10, 20, 2000)])
    assert 0.07 < wrong < 0.13
    biased = OracleJudge(lambda im: float(im.mean()), position_bias=0.2, seed=2)
    first = np.mean([v.overall is Choice.FIRST for v in _verdicts(biased, 10, 20, 2000)])
    assert 0.17 < first < 0.23
