"""make_judge: spec strings to judges, and clear errors for bad ones."""

from __future__ import annotations

import pytest

from intuitf.errors import JudgeError
from intuitf.evaluator.budget import Budget
from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.factory import make_judge
from intuitf.evaluator.mllm import MLLMJudge


def test_provider_specs(monkeypatch):
    monkeypatch.setenv("OPENAI_API_KEY", "k1")
    monkeypatch.setenv("GEMINI_API_KEY", "k2")
    monkeypatch.setenv("OPENROUTER_API_KEY", "k3")
    j = make_judge("openai:gpt-4o-mini", swap="auto")
    assert isinstance(j, MLLMJudge) and j.name == "openai:gpt-4o-mini" and j.swap == "auto"
    assert j.base_url == "https://api.openai.com/v1/"
    g = make_judge("gemini:gemini-2.5-flash")
    assert g.base_url == "https://generativelanguage.googleapis.com/v1beta/openai/"
    assert make_judge("openai").model == "gpt-5.4-mini"  # the preset's current default model
    assert make_judge("gemini").model == "gemini-2.5-flash"  # 2.0-flash is retired
    assert make_judge("ollama:qwen2.5vl:7b").model == "qwen2.5vl:7b"
    assert make_judge("ollama:x").base_url == "http://localhost:11434/v1/"
    assert make_judge("vllm:m").base_url == "http://localhost:8000/v1/"
    assert make_judge("lmstudio:m").base_url == "http://localhost:1234/v1/"
    assert make_judge("openrouter:openai/gpt-4o").base_url == "https://openrouter.ai/api/v1/"


def test_url_specs_and_shared_cache_and_budget():
    cache, budget = VerdictCache(), Budget(max_calls=10)
    j = make_judge("http://127.0.0.1:8123/v1#my-model", cache=cache, budget=budget)
    assert j.model == "my-model" and j.base_url == "http://127.0.0.1:8123/v1/"
    assert j.cache is cache and j.budget is budget
    assert make_judge("http://127.0.0.1:8123/v1").model == "default"
    assert make_judge("https://example.org/v1", model="m2").model == "m2"
    # A provider spec with another base URL (a proxy); a URL spec ignores a second URL.
    monkey = make_judge("ollama:llava", base_url="http://10.0.0.2:11434/v1")
    assert monkey.base_url == "http://10.0.0.2:11434/v1/" and monkey.name == "ollama:llava"
    assert make_judge("http://a:1/v1", base_url="http://b:2/v1").base_url == "http://a:1/v1/"


@pytest.mark.parametrize("spec", ["", "gpt-4o", "anthropic:claude", "ftp://x"])
def test_unknown_specs(spec):
    with pytest.raises(JudgeError) as exc:
        make_judge(spec)
    assert "metric" in exc.value.hint and "openai" in exc.value.hint


def test_bad_options_are_judge_errors():
    with pytest.raises(JudgeError, match="swap"):
        make_judge("ollama:x", swap="sometimes")
    with pytest.raises(JudgeError, match="layout"):
        make_judge("ollama:x", compose="grid")


def test_metric_spec():
    j = make_judge("metric")
    assert j.name.startswith("metric")
