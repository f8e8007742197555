"""The fake multimodal model server, spoken to directly over loopback HTTP."""

from __future__ import annotations

import asyncio
import json
import random
import time

import httpx
import numpy as np
import pytest

from intuitf.evaluator.compose import comparison_images, content_parts
from intuitf.evaluator.prompts import response_format, user_prompt
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer, Latency, main


def _body(first, second, *, structured=True, layout="parts"):
    q = aspects_for("quality")
    content = [{"type": "text", "text": user_prompt(q, Intent(), layout)}]
    content += content_parts(comparison_images(first, second, Intent(), layout))
    body = {"model": "default", "messages": [{"role": "user", "content": content}]}
    if structured:
        body["response_format"] = response_format(q, Intent())
    return body


def test_models_and_json_answer(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target) as srv:
        assert srv.base_url.startswith("http://127.0.0.1:") and srv.port > 0
        models = httpx.get(srv.base_url + "/models").json()
        assert models["data"][0]["id"] == "default"
        r = httpx.post(srv.base_url + "/chat/completions", json=_body(c[5], c[1]))
        assert r.status_code == 200
        data = r.json()
        answer = json.loads(data["choices"][0]["message"]["content"])
        assert {v["choice"] for v in answer["aspects"].values()} == {"second"}
        assert set(answer["aspects"]) == {a.key for a in aspects_for("quality")}
        assert data["usage"]["prompt_tokens"] > 100 and data["usage"]["completion_tokens"] > 0
        # Free text when no schema is asked for, side-by-side composites split correctly.
        r = httpx.post(
            srv.base_url + "/chat/completions",
            json=_body(c[0], c[6], structured=False, layout="side_by_side"),
        )
        text = r.json()["choices"][0]["message"]["content"]
        assert "Final answer:" in text and "[information_richness]: first" in text
        assert srv.stats.requests == 2 and srv.stats.structured_requests == 1


def test_score_function_replaces_target(oracle_images):
    _, c = oracle_images
    # Prefer the darker image, whatever the target.
    with FakeMLLMServer(score=lambda im: -float(im.mean())) as srv:
        darker, brighter = sorted(c[:2], key=lambda im: im.mean())
        r = httpx.post(srv.base_url + "/chat/completions", json=_body(brighter, darker))
        answer = json.loads(r.json()["choices"][0]["message"]["content"])
        assert answer["aspects"]["information_richness"]["choice"] == "second"


def test_concurrent_requests_are_not_serialised(oracle_images):
    target, c = oracle_images
    body = _body(c[0], c[1])

    async def burst(url: str) -> list[int]:
        async with httpx.AsyncClient(timeout=10) as client:
            rs = await asyncio.gather(
                *(client.post(url + "/chat/completions", json=body) for _ in range(50))
            )
        return [r.status_code for r in rs]

    with FakeMLLMServer(target=target, latency=0.5) as srv:
        t0 = time.perf_counter()
        codes = asyncio.run(burst(srv.base_url))
        elapsed = time.perf_counter() - t0
    assert codes == [200] * 50
    assert srv.stats.max_in_flight >= 45
    assert elapsed < 0.5 * 50 / 4  # far from 25 s serial


def test_faults_are_seeded_and_reported(oracle_images):
    target, c = oracle_images
    body = _body(c[0], c[1])
    seen = []
    for _ in range(2):
        with FakeMLLMServer(
            target=target, faults={"rate_limit": 0.5}, retry_after=2, seed=3
        ) as srv:
            codes = []
            for _ in range(12):
                r = httpx.post(srv.base_url + "/chat/completions", json=body)
                codes.append(r.status_code)
                if r.status_code == 429:
                    assert r.headers["retry-after"] == "2"
            seen.append(codes)
            assert srv.stats.faults.get("rate_limit", 0) == codes.count(429)
    assert seen[0] == seen[1]  # same seed, same sequence
    assert 2 <= seen[0].count(429) <= 10


def test_latency_distributions():
    rng = random.Random(0)
    assert Latency.parse(0.25).sample(rng) == 0.25
    u = [Latency.parse("uniform:0.1,0.3").sample(rng) for _ in range(200)]
    assert 0.1 <= min(u) and max(u) <= 0.3 and abs(np.mean(u) - 0.2) < 0.02
    ln = [Latency.parse(("lognormal", 0.5, 0.4)).sample(rng) for _ in range(400)]
    assert abs(np.median(ln) - 0.5) < 0.06
    with pytest.raises(ValueError):
        Latency.parse("gamma:1,2")


def test_bad_configuration():
    with pytest.raises(ValueError, match="target image or a score"):
        FakeMLLMServer()
    with pytest.raises(ValueError, match="unknown fault"):
        FakeMLLMServer(score=float, faults={"explode": 0.1})
    with pytest.raises(SystemExit):
        main(["--fault-rate", "explode=0.1"])
