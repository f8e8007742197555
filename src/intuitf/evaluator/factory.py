"""Making a judge from a short spec string, as the command line and config files give it.

Specs:

- ``"metric"``: the offline :class:`~intuitf.evaluator.metric.MetricJudge` (no model, no network);
- ``"PROVIDER:MODEL"`` for PROVIDER in openai, gemini, ollama, vllm, lmstudio, openrouter
  (``"PROVIDER"`` alone uses the provider's default model);
- ``"http(s)://host:port/v1"`` or ``"http(s)://host:port/v1#MODEL"``: any OpenAI-compatible
  server (model from ``#MODEL``, else the ``model`` option, else "default").

Cloud providers need an API key (environment variable or config file); local servers do not.
"""

from __future__ import annotations

from typing import Any

from intuitf.errors import JudgeError
from intuitf.evaluator.budget import Budget
from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.providers import PROVIDERS
from intuitf.evaluator.types import Judge

_SPEC_HINT = (
    "Use 'metric', PROVIDER:MODEL with PROVIDER one of "
    + ", ".join(PROVIDERS)
    + ", or a server URL such as http://localhost:8000/v1#MODEL."
)


def make_judge(
    spec: str,
    *,
    cache: VerdictCache | None = None,
    budget: Budget | None = None,
    **options: Any,
) -> Judge:
    """A judge for ``spec`` (see the module docs); ``options`` go to the judge's constructor."""
    if not isinstance(spec, str) or not spec.strip():
        raise JudgeError("No judge given.", _SPEC_HINT)
    spec = spec.strip()
    if spec == "metric":
        from intuitf.evaluator.metric import MetricJudge

        return MetricJudge(**options)

    from intuitf.evaluator.mllm import MLLMJudge

    if spec.startswith(("http://", "https://")):
        url, _, model = spec.partition("#")
        options.pop("base_url", None)  # the spec is the URL
        model = model or options.pop("model", None) or "default"
        options.pop("model", None)
        return MLLMJudge(model, base_url=url, cache=cache, budget=budget, **options)
    provider, _, model = spec.partition(":")
    provider = provider.lower()
    if provider not in PROVIDERS:
        raise JudgeError(f"Unknown judge {spec!r}.", _SPEC_HINT)
    model = model or options.pop("model", None)
    options.pop("model", None)
    return MLLMJudge(model or None, provider=provider, cache=cache, budget=budget, **options)
