"""API keys: found in the environment or config file, and never shown in logs, reprs, errors or files."""

from __future__ import annotations

import asyncio
import logging

import pytest

from intuitf.errors import JudgeError
from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.factory import make_judge
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.providers import NO_KEY, PROVIDERS, resolve_api_key
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer

SECRET = "sk-test-9f8e7d6c5b4a-SECRET"
Q = aspects_for("quality")


@pytest.fixture
def no_env_keys(monkeypatch, tmp_path):
    for p in PROVIDERS.values():
        for var in p.key_env:
            monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("INTUITF_CONFIG", str(tmp_path / "absent.toml"))
    return tmp_path


def test_key_never_leaks(oracle_images, tmp_path, caplog, no_env_keys):
    target, c = oracle_images
    path = tmp_path / "v.sqlite"
    caplog.set_level(logging.DEBUG)  # everything, the SDK's and httpx's debug logs included
    with FakeMLLMServer(target=target, faults={"rate_limit": 0.3, "refusal": 0.2}, seed=1) as srv:
        judge = MLLMJudge(
            "default",
            base_url=srv.base_url,
            api_key=SECRET,
            cache=VerdictCache(path),
            backoff_base=0.001,
            max_retries=8,
        )
        for i in range(4):
            asyncio.run(judge.compare(c[i], c[i + 2], Q, Intent()))
    dead = MLLMJudge("default", base_url=srv.base_url, api_key=SECRET, max_retries=0)
    with pytest.raises(JudgeError) as exc:
        asyncio.run(dead.compare(c[0], c[1], Q, Intent()))
    assert srv.stats.faults  # retries and refusals were logged along the way
    assert len(VerdictCache(path)) > 0
    assert SECRET not in caplog.text
    assert SECRET not in repr(judge) and SECRET not in repr(vars(judge))
    assert SECRET not in str(vars(judge)) and SECRET not in str(judge._api_key)
    assert SECRET not in str(exc.value) and SECRET not in repr(exc.value)
    for f in tmp_path.iterdir():
        assert SECRET.encode() not in f.read_bytes(), f.name


def test_missing_key_names_the_variable(no_env_keys):
    with pytest.raises(JudgeError) as exc:
        make_judge("openai:gpt-4o")
    assert "OPENAI_API_KEY" in exc.value.hint
    with pytest.raises(JudgeError, match="GEMINI_API_KEY"):
        make_judge("gemini:gemini-2.0-flash")
    # Local servers need none.
    assert make_judge("ollama:llava")._api_key.reveal() == NO_KEY
    assert make_judge("http://127.0.0.1:9/v1")._api_key.reveal() == NO_KEY


def test_key_from_environment_then_config(no_env_keys, monkeypatch):
    cfg = no_env_keys / "config.toml"
    cfg.write_text('[api_keys]\nopenrouter = "from-config"\nopenai = "config-openai"\n')
    monkeypatch.setenv("INTUITF_CONFIG", str(cfg))
    assert resolve_api_key(PROVIDERS["openrouter"]) == "from-config"
    monkeypatch.setenv("OPENAI_API_KEY", "from-env")
    assert resolve_api_key(PROVIDERS["openai"]) == "from-env"
    assert resolve_api_key(PROVIDERS["openai"], "explicit") == "explicit"
    judge = make_judge("openrouter:anthropic/claude-sonnet-4")
    assert judge.name == "openrouter:anthropic/claude-sonnet-4"
    assert "from-config" not in repr(judge)


def test_broken_config_file_is_a_clear_error_without_its_content(no_env_keys, monkeypatch):
    cfg = no_env_keys / "config.toml"
    cfg.write_text(f'[api_keys]\nopenai = "{SECRET}\n')  # unterminated string
    monkeypatch.setenv("INTUITF_CONFIG", str(cfg))
    with pytest.raises(JudgeError) as exc:
        make_judge("openai:gpt-4o")
    assert str(cfg) in exc.value.message and SECRET not in str(exc.value)
