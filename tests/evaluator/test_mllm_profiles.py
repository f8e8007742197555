"""The judge meets the servers people use: profiles, adapting to 400s, reasoning budgets, rate
limits, billing errors, prices and picture sizes (each case failed on the judge before them)."""

from __future__ import annotations

import asyncio
import json
from types import SimpleNamespace

import httpx
import numpy as np
import openai
import pytest

from intuitf.errors import BudgetExhausted, JudgeError
from intuitf.evaluator.budget import Budget
from intuitf.evaluator.compose import comparison_images, content_parts, decode_data_uri
from intuitf.evaluator.concurrency import AdaptiveLimit
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.pricing import PriceTable
from intuitf.evaluator.profiles import family_of, request_profile
from intuitf.evaluator.responses import _error_fields, _retry_after, _usage
from intuitf.evaluator.types import Choice, Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer

Q = aspects_for("quality")


def _user_turns(body: dict) -> list[dict]:
    return [m for m in body["messages"] if m["role"] != "system"]


# -- profiles ---------------------------------------------------------------------------------


def test_openai_reasoning_models_get_what_they_take():
    r = request_profile("openai", "gpt-5.4-mini")
    assert (r.family, r.token_param, r.send_temperature) == (
        "openai-reasoning",
        "max_completion_tokens",
        False,
    )
    assert r.reasoning_effort == "low" and r.thinking and r.output_tokens >= 4096
    assert family_of("o4-mini").name == "openai-reasoning"
    assert family_of("gpt-4.1").name == "openai-chat"
    assert request_profile("openai", "gpt-4.1").send_temperature
    g3 = request_profile("gemini", "gemini-3-flash-preview")
    assert not g3.send_temperature and g3.reasoning_effort == "low"  # Gemini 3: default temp
    assert request_profile("ollama", "qwen2.5vl:7b").concurrency == 1
    assert request_profile("lmstudio", "x").concurrency == 1
    assert (
        request_profile("gemini", "gemini-2.5-flash", reasoning_effort="default").reasoning_effort
        is None
    )


def test_judge_settings_come_from_the_config(tmp_path, monkeypatch):
    cfg = tmp_path / "config.toml"
    cfg.write_text(
        '[judge]\nmax_output_tokens = 1500\nreasoning_effort = "medium"\nmax_concurrency = 3\n'
        '[prices]\n"my-model" = [1.0, 2.0]\n'
    )
    monkeypatch.setenv("INTUITF_CONFIG", str(cfg))
    j = MLLMJudge("gpt-5.4-mini", provider="openai", api_key="k")
    assert j.max_tokens == 1500 and j.profile.reasoning_effort == "medium"
    assert j.max_concurrency == 3 and j.concurrency == 3
    assert MLLMJudge("my-model", base_url="http://x/v1").prices.lookup("my-model") == (1.0, 2.0)


# -- adapting to what the server says -----------------------------------------------------------


def test_openai_reasoning_preset_sends_no_rejected_parameter(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, personality="openai-reasoning") as srv:
        j = MLLMJudge(
            "gpt-5.4-mini", provider="openai", base_url=srv.base_url, api_key="k", swap="never"
        )
        v = asyncio.run(j.compare(c[0], c[3], Q, Intent()))
        body = srv.requests_log[0]
    assert v.error is None and v.overall is Choice.FIRST
    assert srv.stats.requests == 1 and not srv.stats.rejected and not j.adaptations
    assert body["max_completion_tokens"] >= 4096 and "max_tokens" not in body
    assert "temperature" not in body and body["reasoning_effort"] == "low"


def test_400s_naming_a_parameter_are_fixed_once_and_recorded(oracle_images):
    target, c = oracle_images
    notes = []
    with FakeMLLMServer(target=target, personality="openai-reasoning") as srv:
        # Given only by URL the judge does not know the server: it learns from the 400s.
        j = MLLMJudge("gpt-5.4-mini", base_url=srv.base_url, swap="never", on_adapt=notes.append)
        j.profile.send_temperature = True  # as a server of unknown kind would be asked
        j.profile.token_param = "max_tokens"
        v1 = asyncio.run(j.compare(c[0], c[3], Q, Intent()))
        v2 = asyncio.run(j.compare(c[4], c[1], Q, Intent()))
    assert v1.error is None and v2.error is None and v2.overall is Choice.SECOND
    assert [a["what"] for a in j.adaptations] == ["max_tokens", "temperature"]
    assert notes == j.adaptations and "unsupported" in notes[0]["because"]
    assert srv.stats.rejected == {"max_tokens": 1, "temperature": 1}
    assert j.structured  # rejections of other things never switch structured output off
    assert j.cost.failed_calls == 0 and j.cost.calls == 2


def test_an_unrelated_400_is_an_error_of_that_request_not_of_structured_output(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, personality="vllm-one-image") as srv:
        j = MLLMJudge("not-served", base_url=srv.base_url, swap="never")
        with pytest.raises(JudgeError, match="404"):
            asyncio.run(j.compare(c[0], c[3], Q, Intent()))
        assert j.structured and not j.adaptations


def _answering(status: int, body: object):
    """A fake server whose chat endpoint always answers ``status`` with ``body``."""
    from fastapi import FastAPI
    from fastapi.responses import JSONResponse

    srv = FakeMLLMServer(score=lambda im: 0.0)
    app = FastAPI()

    @app.post("/v1/chat/completions")
    async def chat() -> JSONResponse:
        srv.stats.requests += 1
        return JSONResponse(body, status_code=status)

    srv.app = app
    return srv


def test_a_400_about_something_else_leaves_structured_output_on():
    srv = _answering(400, {"error": {"message": "Invalid image data.", "type": "invalid_request"}})
    img = np.zeros((8, 8, 3), np.uint8)
    with srv:
        j = MLLMJudge("m", base_url=srv.base_url, swap="never")
        with pytest.raises(JudgeError, match="Invalid image data"):
            asyncio.run(j.compare(img, img + 1, Q, Intent()))
    assert j.structured and not j.adaptations and srv.stats.requests == 1


def test_a_server_without_json_schema_gets_json_mode(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, structured="json_object") as srv:
        j = MLLMJudge("default", base_url=srv.base_url, swap="never")
        v1 = asyncio.run(j.compare(c[0], c[3], Q, Intent()))
        v2 = asyncio.run(j.compare(c[4], c[1], Q, Intent()))
    assert v1.overall is Choice.FIRST and v2.overall is Choice.SECOND and v2.rationale
    assert j.profile.structured == "json_object" and j.structured
    assert [a["what"] for a in j.adaptations] == ["response_format=json_schema"]
    assert srv.requests_log[-1]["response_format"] == {"type": "json_object"}
    assert srv.stats.requests == 3


def test_unsupported_effort_value_is_replaced_by_a_listed_one():
    err = openai.BadRequestError(
        "bad",
        response=httpx.Response(400, request=httpx.Request("POST", "http://x")),
        body={
            "error": {
                "message": "Unsupported value: 'low' is not supported with the 'gpt-5-pro' "
                "model. Supported values are: 'high'.",
                "param": "reasoning_effort",
                "code": "unsupported_value",
            }
        },
    )
    j = MLLMJudge("gpt-5-pro", provider="openai", api_key="k")
    kwargs = j._request([], {"type": "json_schema"}, 100)
    assert j._adapt(400, *_error_fields(err), kwargs)
    assert j.profile.reasoning_effort == "high"


def test_one_image_server_gets_the_candidates_side_by_side(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, personality="vllm-one-image") as srv:
        j = MLLMJudge(provider="vllm", base_url=srv.base_url, swap="never")
        v = asyncio.run(j.compare(c[6], c[0], Q, Intent()))
        assert j.model == "Qwen/Qwen2.5-VL-7B-Instruct"  # found with GET /v1/models
        assert v.error is None and v.overall is Choice.SECOND
        assert j.profile.max_images == 1 and srv.stats.rejected == {"images": 1}
        with pytest.raises(JudgeError, match="image"):  # a reference needs a second image
            asyncio.run(
                j.compare(c[6], c[0], aspects_for("image"), Intent(kind="image", reference=c[1]))
            )


def test_lmstudio_model_is_found_with_get_models(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, personality="lmstudio", latency=0.0) as srv:
        j = MLLMJudge(provider="lmstudio", base_url=srv.base_url, swap="never")
        assert j.concurrency == 1
        v = asyncio.run(j.compare(c[0], c[3], Q, Intent()))
    assert v.error is None and j.model == "qwen2.5-vl-7b-instruct"
    assert srv.requests_log[0]["model"] == "qwen2.5-vl-7b-instruct"


# -- reasoning and thinking models ----------------------------------------------------------------


def test_thoughts_that_spend_the_budget_raise_it_and_no_empty_turn_is_sent(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, personality="gemini-thinking") as srv:
        j = MLLMJudge(
            "gemini-2.5-flash",
            provider="gemini",
            base_url=srv.base_url,
            api_key="k",
            swap="never",
            max_output_tokens=1024,
            reasoning_effort="medium",  # 2000 thought tokens
        )
        v = asyncio.run(j.compare(c[0], c[3], Q, Intent()))
    budgets = [b["max_tokens"] for b in srv.requests_log]
    assert budgets == [1024, 2048, 4096]  # doubled until the thoughts and the answer fit
    assert v.error is None and v.overall is Choice.FIRST and v.retries == 2
    assert j.max_tokens == budgets[-1]  # later questions start with the budget that worked
    assert "empty parts" not in srv.stats.rejected
    assert all(m["role"] != "assistant" for b in srv.requests_log for m in b["messages"])
    # Thoughts are billed: Gemini counts them in total_tokens only.
    assert j.cost.output_tokens == srv.stats.output_tokens > 2000


def test_gemini_3_is_sent_no_temperature(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, personality="gemini-thinking") as srv:
        j = MLLMJudge(
            "gemini-3-flash-preview",
            provider="gemini",
            base_url=srv.base_url,
            api_key="k",
            swap="never",
        )
        v = asyncio.run(j.compare(c[0], c[3], Q, Intent()))
    assert v.error is None and "temperature" not in srv.requests_log[0]


def test_retired_gemini_model_says_what_to_use(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target, personality="gemini-thinking") as srv:
        j = MLLMJudge("gemini-2.0-flash", provider="gemini", base_url=srv.base_url, api_key="k")
        with pytest.raises(JudgeError) as exc:
            asyncio.run(j.compare(c[0], c[3], Q, Intent()))
    assert "no longer available" in exc.value.message and "gemini-2.5-flash" in exc.value.hint


# -- rate limits, billing, concurrency --------------------------------------------------------------


def _response(headers: dict) -> SimpleNamespace:
    return SimpleNamespace(headers=httpx.Headers(headers))


def test_rate_limit_hints():
    assert _retry_after(_response({"retry-after-ms": "1500"})) == 1.5
    assert _retry_after(_response({"retry-after": "2"})) == 2.0
    assert (
        _retry_after(
            _response({"x-ratelimit-reset-requests": "1s", "x-ratelimit-reset-tokens": "6m0s"})
        )
        == 360.0
    )
    assert _retry_after(_response({"x-ratelimit-reset-tokens": "20ms"})) == pytest.approx(0.02)
    body = [{"error": {"code": 429, "details": [{"retryDelay": "37s"}]}}]
    assert _retry_after(_response({}), body) == 37.0
    assert _retry_after(_response({}), {"error": {"message": "slow down"}}) is None


def test_low_rpm_server_is_waited_out_by_its_retry_delay(oracle_images):
    target, c = oracle_images
    pairs = [(i, j) for i in range(8) for j in range(8) if i < j][:20]
    with FakeMLLMServer(target=target, personality="gemini-thinking") as srv:
        j = MLLMJudge(
            "gemini-2.5-flash", provider="gemini", base_url=srv.base_url, api_key="k", swap="never"
        )

        async def run():
            return await asyncio.gather(*(j.compare(c[a], c[b], Q, Intent()) for a, b in pairs))

        verdicts = asyncio.run(run())
    assert all(v.error is None for v in verdicts)
    assert srv.stats.rejected.get("rate", 0) > 0 and j.rate_limited > 0
    assert j.cost.failed_calls == srv.stats.rejected["rate"]


@pytest.mark.parametrize(
    "status, body",
    [
        (429, {"error": {"message": "You exceeded your current quota, please check your plan "
                         "and billing details.", "type": "insufficient_quota",
                         "code": "insufficient_quota"}}),
        (402, {"error": {"message": "Insufficient credits", "code": 402}}),
        (429, {"error": {"message": "Error code insufficient_quota: add credit."}}),
    ],
)  # fmt: skip
def test_no_credit_stops_with_a_billing_message(status, body):
    srv = _answering(status, body)
    with srv:
        j = MLLMJudge("m", base_url=srv.base_url, swap="never", max_retries=4)
        img = np.zeros((8, 8, 3), np.uint8)
        with pytest.raises(BudgetExhausted) as exc:
            asyncio.run(j.compare(img, img + 1, Q, Intent()))
    assert "credit or quota" in exc.value.message and srv.stats.requests == 1


def test_one_slot_server_is_not_flooded(oracle_images):
    target, c = oracle_images
    pairs = [(i, (i + 1) % 8) for i in range(8)]
    with FakeMLLMServer(target=target, personality="ollama", latency=0.05) as srv:
        j = MLLMJudge(provider="ollama", base_url=srv.base_url, swap="always", timeout=5.0)

        async def run():
            return await asyncio.gather(*(j.compare(c[a], c[b], Q, Intent()) for a, b in pairs))

        verdicts = asyncio.run(run())
    assert all(v.error is None for v in verdicts) and j.model == "qwen2.5vl:7b"
    assert srv.stats.max_in_flight <= j.max_concurrency == 4 and j.cost.failed_calls == 0


def test_adaptive_limit_halves_on_overload_and_grows_back():
    async def run():
        lim = AdaptiveLimit(8, 16, cooldown=0.0)
        assert lim.overloaded() and lim.width == 4
        lim.overloaded()
        lim.overloaded()
        assert lim.width == 1 and not lim.overloaded()  # never below one
        for _ in range(1 + 2 + 3):
            lim.answered()
        assert lim.width == 4 and lim.cuts == 3
        lim.pause(0.05)
        async with lim.slot():
            pass

    asyncio.run(run())


# -- money ----------------------------------------------------------------------------------------


def test_prices_of_current_models_and_no_prefix_mixups():
    t = PriceTable()
    for model in (
        "gpt-5.4-mini",
        "gpt-5-mini",
        "o4-mini",
        "gemini-3-flash-preview",
        "gemini-2.5-flash",
    ):
        assert t.known(model), model
    assert t.lookup("gemini-2.5-flash-lite") != t.lookup("gemini-2.5-flash")
    only_flash = PriceTable({"gemini-2.5-flash": (0.3, 2.5)})
    assert only_flash.lookup("gemini-2.5-flash-lite") is None
    assert only_flash.lookup("gemini-2.5-flash-preview-09-2025") == (0.3, 2.5)
    assert t.lookup("google/gemini-2.5-flash:thinking") == t.lookup("gemini-2.5-flash")


def test_money_budget_needs_a_price():
    with pytest.raises(JudgeError, match="--price"):
        MLLMJudge("mystery-model", base_url="http://x/v1", budget=Budget(max_usd=1.0))
    MLLMJudge("mystery-model", base_url="http://x/v1", budget=Budget(max_usd=1.0), price=(1, 2))
    MLLMJudge("mystery-model", base_url="http://x/v1", budget=Budget(max_usd=1.0), unpriced=True)
    MLLMJudge("qwen2.5vl:7b", provider="ollama", budget=Budget(max_usd=1.0))  # local: free
    MLLMJudge("m", base_url="http://x/v1", budget=Budget(max_calls=5))  # calls need no price


def test_usage_bills_reasoning_and_the_servers_own_cost():
    apart = SimpleNamespace(
        usage=SimpleNamespace(prompt_tokens=100, completion_tokens=20, total_tokens=920)
    )
    assert _usage(apart) == (100, 820)
    inside = SimpleNamespace(
        usage=SimpleNamespace(prompt_tokens=100, completion_tokens=820, total_tokens=920)
    )
    assert _usage(inside) == (100, 820)
    from intuitf.evaluator.responses import _provider_cost

    resp = openai.types.chat.ChatCompletion.model_validate(
        {
            "id": "x", "object": "chat.completion", "created": 0, "model": "m",
            "choices": [],
            "usage": {"prompt_tokens": 1, "completion_tokens": 1, "total_tokens": 2, "cost": 0.0123},
        }
    )  # fmt: skip
    assert _provider_cost(resp) == 0.0123


# -- pictures ---------------------------------------------------------------------------------------


def test_reference_photo_is_sized_for_the_judge():
    rng = np.random.default_rng(0)
    photo = rng.integers(0, 255, (2400, 3600, 3), np.uint8)  # an 8.6-megapixel photo of noise
    cand = np.zeros((256, 256, 3), np.uint8)
    images = comparison_images(cand, cand, Intent(kind="image", reference=photo))
    assert max(images[0].image.shape[:2]) == 256
    parts = content_parts(images, "png", 90, max_bytes=4_000_000)
    ref_uri = parts[1]["image_url"]["url"]
    assert ref_uri.startswith("data:image/jpeg")  # noise is large as PNG
    assert decode_data_uri(ref_uri).shape[:2] == (171, 256)
    assert sum(len(p["image_url"]["url"]) for p in parts if p["type"] == "image_url") < 1_000_000
    # Small, flat pictures (strokes, outlines) stay lossless.
    flat = np.full((256, 256, 3), 40, np.uint8)
    small = content_parts(comparison_images(cand, cand, Intent(kind="image", reference=flat)))
    assert small[1]["image_url"]["url"].startswith("data:image/png")


def test_request_size_cap_reencodes_until_it_fits():
    rng = np.random.default_rng(1)
    big = rng.integers(0, 255, (1024, 1024, 3), np.uint8)
    images = comparison_images(big, big, Intent())
    loose = content_parts(images, "png")
    capped = content_parts(images, "png", 90, max_bytes=1_000_000)
    size = sum(len(p["image_url"]["url"]) for p in capped if p["type"] == "image_url")
    assert (
        size
        <= 1_000_000
        < sum(len(p["image_url"]["url"]) for p in loose if p["type"] == "image_url")
    )
    with pytest.raises(JudgeError, match="request limit"):
        content_parts(images, "png", 90, max_bytes=1000)


def test_request_log_shortens_images(oracle_images):
    target, c = oracle_images
    with FakeMLLMServer(target=target) as srv:
        asyncio.run(
            MLLMJudge("default", base_url=srv.base_url, swap="never").compare(
                c[0], c[1], Q, Intent()
            )
        )
    text = json.dumps(srv.requests_log[0])
    assert "bytes>" in text and len(text) < 20_000


def test_optimize_refuses_a_money_budget_for_a_model_of_unknown_price(tmp_path):
    import subprocess
    import sys

    run = tmp_path / "r"
    proc = subprocess.run(
        [sys.executable, "-m", "intuitf", "optimize", "phantom", "--evaluator",
         "http://127.0.0.1:9/v1#mystery", "--budget-usd", "1", "-o", str(run)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    said = " ".join((proc.stdout + proc.stderr).split())
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "No price is known" in said and "--price" in said and "--unpriced" in said
    assert not (run / "run.json").exists()


def test_a_400_that_stays_after_its_fix_is_not_asked_again_until_the_deadline(
    oracle_images, monkeypatch
):
    # A question put in a form the profile does not describe used to be "fixed" and resent
    # in a loop for the whole answer deadline (about 950 requests against the fake server).
    target, c = oracle_images
    body = {"error": {"message": "response_format is not supported", "param": "response_format",
                      "code": "unsupported_parameter", "type": "invalid_request_error"}}  # fmt: skip
    srv = _answering(400, body)
    with srv:
        j = MLLMJudge("m", base_url=srv.base_url, swap="never", max_retries=0)
        monkeypatch.setattr(j, "_adapt", lambda *a, **k: True)  # believes every 400 fixed
        with pytest.raises(JudgeError, match="400"):
            asyncio.run(j.compare(c[0], c[3], Q, Intent()))
    assert srv.stats.requests == 7  # the question and six resends, then its error
