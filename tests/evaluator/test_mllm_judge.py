"""MLLMJudge against the fake model server over real loopback HTTP: preferences and debiasing."""

from __future__ import annotations

import asyncio
import itertools

import numpy as np
import pytest

from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.types import Choice, Intent, Judge
from intuitf.intent.aspects import aspects_for, aspects_for_intent
from intuitf.testing.fake_mllm import FakeMLLMServer

Q = aspects_for("quality")


def _pairs(c, n=6):
    """Ordered pairs (i, j), i != j, among the first n candidates: the better one is min(i, j)."""
    return [(i, j) for i, j in itertools.permutations(range(n), 2)]


async def _judge_all(judge, c, pairs, aspects=Q, intent=None):
    intent = intent or Intent()
    return await asyncio.gather(*(judge.compare(c[i], c[j], aspects, intent) for i, j in pairs))


@pytest.mark.parametrize("swap", ["never", "always", "auto"])
def test_correct_preferences_at_noise_zero(oracle_images, swap):
    target, c = oracle_images
    pairs = _pairs(c, 5)
    with FakeMLLMServer(target=target) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap=swap)
        assert isinstance(judge, Judge) and judge.name == "url:default"
        verdicts = asyncio.run(_judge_all(judge, c, pairs))
    for (i, j), v in zip(pairs, verdicts, strict=True):
        want = Choice.FIRST if i < j else Choice.SECOND
        assert v.overall is want and v.error is None
        assert set(v.per_aspect.values()) == {want}
        assert v.p_first == (1.0 if want is Choice.FIRST else 0.0)
    calls = {"never": 1, "always": 2, "auto": 1}[swap] * len(pairs)
    assert srv.stats.requests == calls == judge.cost.calls


def test_swap_debiasing_cancels_position_bias(oracle_images):
    target, c = oracle_images
    pairs = _pairs(c, 6)
    results = {}
    for swap in ("never", "always", "auto"):
        with FakeMLLMServer(target=target, position_bias=0.6, seed=1) as srv:
            judge = MLLMJudge("default", base_url=srv.base_url, swap=swap)
            verdicts = asyncio.run(_judge_all(judge, c, pairs))
        wrong = first = 0
        for (i, j), v in zip(pairs, verdicts, strict=True):
            want = Choice.FIRST if i < j else Choice.SECOND
            wrong += v.overall is want.swapped()
            first += v.overall is Choice.FIRST
        results[swap] = (wrong, first)
    n = len(pairs)
    # One order: the biased model picks the first image most of the time, often wrongly.
    assert results["never"][1] > 0.7 * n and results["never"][0] > 0.2 * n
    # Both orders: a biased answer meets its mirror and becomes a tie, never a wrong verdict.
    assert results["always"][0] == 0
    # Content-chosen order: the bias is no longer a lean towards the caller's first image.
    assert results["auto"][1] < 0.7 * n


def test_json_and_free_text_and_side_by_side(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target) as srv:
        for structured, compose, fmt in [
            (True, "parts", "png"),
            (False, "parts", "jpeg"),
            (True, "side_by_side", "png"),
            (False, "side_by_side", "jpeg"),
        ]:
            judge = MLLMJudge(
                "default",
                base_url=srv.base_url,
                swap="never",
                structured=structured,
                compose=compose,
                image_format=fmt,
            )
            v = asyncio.run(judge.compare(c[6], c[0], Q, Intent()))
            assert v.overall is Choice.SECOND and v.error is None, (structured, compose)
            assert bool(v.rationale) is structured  # JSON analyses are kept
    assert srv.stats.structured_requests == 2


def test_structured_output_falls_back_to_text_once(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, structured=False) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never")
        v1 = asyncio.run(judge.compare(c[0], c[3], Q, Intent()))
        assert judge.structured is False
        v2 = asyncio.run(judge.compare(c[4], c[1], Q, Intent()))
    assert v1.overall is Choice.FIRST and v2.overall is Choice.SECOND
    # One rejected structured request, then plain text only.
    assert srv.stats.requests == 3 and srv.stats.answered == 2
    assert judge.cost.calls == 2 and judge.cost.failed_calls == 0


def test_every_intent_kind_reaches_the_candidates(oracle_images):
    target, c = oracle_images
    h, w = target.shape[:2]
    strokes = np.zeros((h, w, 4), np.uint8)
    strokes[5:15, 5:15] = (0, 255, 0, 255)
    intents = [
        Intent(kind="text", text="bright red structures", about="a test pattern"),
        Intent(kind="image", reference=c[7]),
        Intent(kind="sketch", sketch=strokes, base=c[4]),
        Intent(kind="edit", text="make the selected feature blue", base=c[4], selected=(1,)),
    ]
    with FakeMLLMServer(target=target) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never")
        for intent in intents:
            aspects = aspects_for_intent(intent)
            v = asyncio.run(judge.compare(c[1], c[2], aspects, intent))
            assert v.overall is Choice.FIRST and v.error is None, intent.kind
            assert set(v.per_aspect) == {a.key for a in aspects}
            # The model's interpretation of the reference is kept with the verdict.
            assert ("reference_description" in v.rationale) is (intent.kind == "image")


def test_concurrency_limit_is_respected(oracle_images):
    target, c = oracle_images
    pairs = _pairs(c, 5)  # 20 comparisons
    with FakeMLLMServer(target=target, latency=0.03) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never", max_concurrency=3)
        asyncio.run(_judge_all(judge, c, pairs))
        assert srv.stats.max_in_flight == 3
        wide = MLLMJudge("default", base_url=srv.base_url, swap="always", max_concurrency=64)
        srv.stats.max_in_flight = 0
        asyncio.run(_judge_all(wide, c, pairs))
        assert srv.stats.max_in_flight > 10
