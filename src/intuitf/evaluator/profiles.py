"""What each model server and model family takes: one table, with the date it was checked.

A judge's request is built from two profiles: the **provider's** (the server: which token-limit
parameter it names, whether it takes a JSON schema, how many requests it serves at once, whether
the served model is found with ``GET /v1/models``) and the **model family's** (whether the model
reasons before answering, takes a temperature, takes ``reasoning_effort``). :func:`request_profile`
merges them into a :class:`RequestProfile`, which the judge then adapts when a server says
otherwise (HTTP 400 naming a parameter; see :mod:`intuitf.evaluator.mllm`).

Checked on 2026-11-26 against the providers' documentation (sources below, read through the
project's documentation search):

- OpenAI reasoning models (o-series, the gpt-5 family): ``max_completion_tokens`` (reasoning
  tokens count against it), only the default temperature, ``reasoning_effort``; gpt-5 takes
  minimal/low/medium/high, gpt-5.1 and later none/low/medium/high(/xhigh), gpt-5-pro only high,
  so the judge sends "low", which all but gpt-5-pro take (that one answers 400
  ``unsupported_value`` listing its values, and the judge adopts one of them).
  developers.openai.com/api/docs/guides/reasoning; learn.microsoft.com ReasoningEffort;
  the 400 body shape from github.com/anomalyco/opencode/issues/4451.
  The docs recommend gpt-5.4-mini "for lower cost and latency": the preset's default.
- Gemini (OpenAI-compatible endpoint): 2.5 models think with a token budget, Gemini 3 with levels
  (``reasoning_effort`` low/medium/high maps to both); thoughts spend the output budget; Gemini 3
  is tuned for the default temperature 1.0 (lower causes looping), so none is sent.
  ai.google.dev/gemini-api/docs/gemini-3, firebase.google.com/docs/ai-logic/thinking,
  docs.rs adk-model ThinkingLevel. ``gemini-2.0-flash`` is retired (404 "no longer available");
  the preset's default is the stable ``gemini-2.5-flash``.
- Ollama and LM Studio serve one request at a time unless configured otherwise
  (``OLLAMA_NUM_PARALLEL``); LM Studio needs the loaded model's id; vLLM's V0 engine takes one
  image per request unless started with ``--limit-mm-per-prompt``.

Prices: USD per million input and output tokens, list prices on :data:`PRICES_CHECKED`, with the
source of each group named next to it. A ``[prices]`` table in the config file overrides them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from typing import Literal

TokenParam = Literal["max_tokens", "max_completion_tokens"]
#: How the judge asks for JSON: a strict schema, any JSON object, or only the prompt's words.
StructuredMode = Literal["json_schema", "json_object", "text"]
STRUCTURED_MODES: tuple[StructuredMode, ...] = ("json_schema", "json_object", "text")

#: When the profiles and prices below were last checked against the providers' documentation.
CHECKED = "2026-11-26"
PRICES_CHECKED = "2026-11-26"

#: Output budget (tokens) for a model that answers directly, and for one that reasons first
#: (its reasoning spends the same budget). An empty answer cut off by the budget doubles it for
#: the re-ask, up to :data:`MAX_OUTPUT_TOKENS`.
PLAIN_OUTPUT_TOKENS = 2048
THINKING_OUTPUT_TOKENS = 4096
MAX_OUTPUT_TOKENS = 32768


@dataclass(frozen=True)
class ModelFamily:
    """What a family of models takes, recognised by its name (vendor prefix removed)."""

    name: str
    pattern: str
    #: Whether a judging temperature may be sent (False: leave the model's default).
    temperature: bool = True
    #: The reasoning effort sent by default (None: none is sent).
    reasoning_effort: str | None = None
    #: Whether the model reasons before answering, spending the output budget on it.
    thinking: bool = False
    #: The token-limit parameter the family needs regardless of the server (None: the server's).
    token_param: TokenParam | None = None
    #: Said when the model is known to be retired.
    retired: str | None = None

    def matches(self, model: str) -> bool:
        return re.search(self.pattern, base_name(model), re.IGNORECASE) is not None


FAMILIES: tuple[ModelFamily, ...] = (
    ModelFamily(
        "openai-reasoning",
        r"^(o\d+(-mini|-pro)?|gpt-5(?!.*-chat))",
        temperature=False,
        reasoning_effort="low",
        thinking=True,
        token_param="max_completion_tokens",
    ),
    ModelFamily("openai-chat", r"^(gpt-4o|gpt-4\.1|gpt-4|chatgpt|gpt-5.*-chat)"),
    ModelFamily("gemini-3", r"^gemini-3", temperature=False, reasoning_effort="low", thinking=True),
    ModelFamily("gemini-2.5", r"^gemini-2\.5", reasoning_effort="low", thinking=True),
    ModelFamily(
        "gemini-retired",
        r"^gemini-(1\.|2\.0)",
        retired="Gemini 1.x and 2.0 models are retired; use gemini-2.5-flash or gemini-3-flash.",
    ),
    # Open models that write their reasoning into the answer (<think> ... </think>).
    ModelFamily(
        "open-reasoning", r"(qwen3|deepseek-r1|qwq|thinking|magistral|glm-4\.[5-9]v)", thinking=True
    ),
    ModelFamily("generic", r""),
)


@dataclass(frozen=True)
class ProviderProfile:
    """What a kind of server takes and how hard it may be pushed."""

    name: str
    token_param: TokenParam = "max_tokens"
    structured: StructuredMode = "json_schema"
    #: Requests in flight to start with (the judge grows and shrinks this as answers come).
    concurrency: int = 4
    #: Images one request may carry (None: as many as the comparison needs).
    max_images: int | None = None
    #: Whether the served model is found with ``GET /v1/models`` when none is named.
    discover_model: bool = False
    #: Whether calls cost nothing (a server on the user's own machine).
    free: bool = False
    #: Whether the server takes ``reasoning_effort``.
    reasoning_effort: bool = False


PROVIDER_PROFILES: dict[str, ProviderProfile] = {
    p.name: p
    for p in (
        # OpenAI deprecated max_tokens; max_completion_tokens works for every current model.
        ProviderProfile("openai", "max_completion_tokens", concurrency=8, reasoning_effort=True),
        # Free tiers allow 5-15 requests per minute: start low; 429s carry retryDelay in the body.
        ProviderProfile("gemini", concurrency=4, reasoning_effort=True),
        ProviderProfile("openrouter", concurrency=8, reasoning_effort=True),
        # One request at a time by default (OLLAMA_NUM_PARALLEL=1; LM Studio likewise).
        ProviderProfile("ollama", concurrency=1, discover_model=True, free=True),
        ProviderProfile("lmstudio", concurrency=1, discover_model=True, free=True),
        # vLLM batches requests well; its V0 engine takes one image unless told otherwise (the
        # judge learns the limit from the 400 it answers).
        ProviderProfile("vllm", concurrency=4, discover_model=True, free=True),
        # A server given by URL: most likely a local one, so start gently.
        ProviderProfile("url", concurrency=2, discover_model=True),
    )
}

#: USD per 1M (input, output) tokens. Sources, read on PRICES_CHECKED:
#: OpenAI: developers.openai.com/api/docs/pricing (via the 2026-11-06 apievangelist summary and
#: apidog/dev.to for gpt-5.4-mini/nano); gpt-5 family and o-series as listed there.
#: Gemini: ai.google.dev/gemini-api/docs/pricing (2.5 flash via openrouter.ai and vercel.com model
#: pages; gemini-3-flash via the official price quoted on muapi.ai); thinking tokens are billed
#: as output. Anthropic: anthropic.com/pricing.
PRICES: dict[str, tuple[float, float]] = {
    # OpenAI
    "gpt-5.4": (5.00, 20.00),
    "gpt-5.4-mini": (0.75, 4.50),
    "gpt-5.4-nano": (0.20, 1.25),
    "gpt-5": (1.25, 10.00),
    "gpt-5-mini": (0.25, 2.00),
    "gpt-5-nano": (0.05, 0.40),
    "gpt-5.1": (1.25, 10.00),
    "o3": (2.00, 8.00),
    "o4-mini": (1.10, 4.40),
    "gpt-4o": (2.50, 10.00),
    "gpt-4o-mini": (0.15, 0.60),
    "gpt-4.1": (2.00, 8.00),
    "gpt-4.1-mini": (0.40, 1.60),
    "gpt-4.1-nano": (0.10, 0.40),
    # Google
    "gemini-3-flash": (0.50, 3.00),
    "gemini-3-flash-preview": (0.50, 3.00),
    "gemini-3-pro-preview": (2.00, 12.00),
    "gemini-2.5-pro": (1.25, 10.00),
    "gemini-2.5-flash": (0.30, 2.50),
    "gemini-2.5-flash-lite": (0.10, 0.40),
    "gemini-2.0-flash": (0.10, 0.40),
    "gemini-2.0-flash-001": (0.10, 0.40),
    # Anthropic (through OpenRouter)
    "claude-sonnet-4": (3.00, 15.00),
    "claude-sonnet-4.5": (3.00, 15.00),
}

#: The default model of each preset (see :mod:`intuitf.evaluator.providers`).
DEFAULT_MODELS: dict[str, str] = {
    "openai": "gpt-5.4-mini",
    "gemini": "gemini-2.5-flash",
    "openrouter": "openai/gpt-5.4-mini",
    "ollama": "qwen2.5vl:7b",
    "vllm": "Qwen/Qwen2.5-VL-7B-Instruct",
    "lmstudio": "",  # the loaded model, found with GET /v1/models
}


def base_name(model: str) -> str:
    """The model's name without a "vendor/" prefix or an OpenRouter ":variant" suffix."""
    return model.rsplit("/", 1)[-1].split(":", 1)[0] if "/" in model else model


def family_of(model: str) -> ModelFamily:
    """The first family whose pattern matches ``model`` (the generic one at worst)."""
    for fam in FAMILIES:
        if fam.matches(model):
            return fam
    return FAMILIES[-1]


def provider_profile(provider: str) -> ProviderProfile:
    """The profile of a provider preset, or of a server given by URL."""
    return PROVIDER_PROFILES.get(provider, PROVIDER_PROFILES["url"])


@dataclass
class RequestProfile:
    """What the judge sends, merged from the provider and the model family; adapted in place
    when the server rejects something (each adaptation is listed in ``adapted``)."""

    provider: str
    family: str
    token_param: TokenParam
    send_temperature: bool
    reasoning_effort: str | None
    structured: StructuredMode
    max_images: int | None
    output_tokens: int
    thinking: bool
    concurrency: int
    free: bool
    adapted: list[dict] = field(default_factory=list)

    def copy(self) -> RequestProfile:
        return replace(self, adapted=list(self.adapted))


def request_profile(
    provider: str,
    model: str,
    *,
    structured: bool = True,
    output_tokens: int | None = None,
    reasoning_effort: str | None = None,
) -> RequestProfile:
    """What to send to ``model`` at ``provider``.

    ``output_tokens`` None: the family's default budget. ``reasoning_effort`` None: the family's
    default where the server takes one; "default" sends none (the model's own default).
    """
    p = provider_profile(provider)
    fam = family_of(model)
    if reasoning_effort is None:
        # A server given by URL may be a proxy of a cloud model: its family decides (a server
        # that does not take the parameter says so, and the judge stops sending it).
        effort = fam.reasoning_effort if p.reasoning_effort or p.name == "url" else None
    elif reasoning_effort == "default":
        effort = None
    else:
        effort = reasoning_effort
    thinking = fam.thinking and effort not in ("none",)
    budget = output_tokens or (THINKING_OUTPUT_TOKENS if fam.thinking else PLAIN_OUTPUT_TOKENS)
    return RequestProfile(
        provider=p.name,
        family=fam.name,
        token_param=fam.token_param if p.name == "openai" and fam.token_param else p.token_param,
        send_temperature=fam.temperature,
        reasoning_effort=effort,
        structured=p.structured if structured else "text",
        max_images=p.max_images,
        output_tokens=int(budget),
        thinking=thinking,
        concurrency=p.concurrency,
        free=p.free,
    )


def compatibility_rows() -> list[tuple[str, str, str]]:
    """(provider, model family, what intuitf sends) for the README's compatibility table."""
    examples = {
        "openai": ("gpt-5.4-mini", "o4-mini", "gpt-4.1"),
        "gemini": ("gemini-2.5-flash", "gemini-3-flash-preview"),
        "openrouter": ("openai/gpt-5.4-mini", "google/gemini-2.5-flash"),
        "ollama": ("qwen2.5vl:7b", "qwen3-vl:8b"),
        "lmstudio": ("qwen2.5-vl-7b-instruct",),
        "vllm": ("Qwen/Qwen2.5-VL-7B-Instruct",),
    }
    rows = []
    for provider, models in examples.items():
        for model in models:
            r = request_profile(provider, model)
            sends = [f"{r.token_param}={r.output_tokens}"]
            sends.append("temperature=0" if r.send_temperature else "no temperature")
            if r.reasoning_effort:
                sends.append(f"reasoning_effort={r.reasoning_effort}")
            sends.append(f"response_format={r.structured}")
            sends.append(f"{r.concurrency} at once to start")
            rows.append((provider, f"{family_of(model).name} ({model})", ", ".join(sends)))
    return rows
