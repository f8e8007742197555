"""MLLMJudge: a multimodal model compares two renderings over the OpenAI chat-completions protocol.

One ``AsyncOpenAI`` client per judge (per event loop) reaches OpenAI, Gemini, Ollama, vLLM, LM
Studio, OpenRouter or any compatible server. What a request carries follows the provider's and
the model family's profile (:mod:`intuitf.evaluator.profiles`: token-limit parameter,
temperature, reasoning effort, structured-output mode, images per request). A 400 that names
one of these is fixed once (renamed or dropped parameter, JSON schema → JSON object → plain
text, fewer images) and listed in :attr:`MLLMJudge.adaptations`; any other 400 is an error of
that request. The SDK's own retries are off; this module retries with exponential backoff and
jitter, waiting as long as the server asks (``Retry-After``, ``retry-after-ms``,
``x-ratelimit-reset-*``, Gemini's ``retryDelay``), and keeps as many requests in flight as the
server bears (:class:`~intuitf.evaluator.concurrency.AdaptiveLimit`). HTTP 402 and
``insufficient_quota`` raise :class:`~intuitf.errors.BudgetExhausted` with a billing message.

**Unusable answers are asked again.** An answer with no readable choice (unparseable or cut
off) is followed up with a corrective message ("answer only with the JSON object ..."), a
refusal with a short explanation of the task (once: a second refusal is final), and a "blind"
answer (the model says it cannot see the images) by sending the question again, and an empty
answer cut off by the output budget (a reasoning model's thoughts spent it) with twice the
budget; an empty assistant turn is never sent. At most ``answer_retries`` times per answer (by
default the retry budget, ``max_retries``). Only when every try was unusable does the comparison
become a *logged tie* (``Verdict.error`` set, the verdict *undecided*, not cached). ``Verdict.retries``
says how many re-asks a verdict took.

**Failure rule.** It raises :class:`~intuitf.errors.JudgeError` when the server gives no answer
after ``max_retries`` retries or within ``deadline`` seconds (unreachable, timeouts, 429 or 5xx
every time) or rejects the request itself (bad key, unknown model): a session should then stop,
keep what it has (every paid answer is already in the cache) and resume later. Each request
waits at most ``timeout`` seconds, so a server that accepts connections but never answers fails
an answer within ``deadline`` (defaults 30 s and 60 s, or ``[judge]`` in the config file); for a
while after that, other answers fail at once instead of waiting for the same dead server.
:class:`~intuitf.errors.BudgetExhausted` is raised *before* a call that would go past the budget.

**Spend.** With a verdict store, every request is recorded in it before it is sent and settled
when answered (usable or not), so the run's spend is exact across kills and resumes (see
:mod:`intuitf.evaluator.cache`).

**Swap debiasing** (``swap``):

- ``"always"``: ask in both orders (concurrently); per aspect, the two answers are averaged, so
  opposite answers make a tie and a decisive answer plus a tie leans to the decisive side.
- ``"never"``: one call, in the order given.
- ``"auto"``: one call, in an order fixed by the two images' content (not by the order the
  caller passes them), so a model's position bias falls at random on either candidate instead of
  systematically favouring the one a tournament lists first; the swapped order is asked only when
  the first answer leaves the overall preference undecided (a tie or an unusable answer). About
  half the cost of "always"; position bias becomes noise rather than a systematic error.
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import random
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import openai
from openai import AsyncOpenAI

from intuitf.errors import BudgetExhausted, JudgeError, RunCancelled
from intuitf.evaluator.budget import Budget
from intuitf.evaluator.cache import VerdictCache, request_key
from intuitf.evaluator.compose import (
    ImageFormat,
    LabelledImage,
    Layout,
    comparison_images,
    content_parts,
    intent_images,
)
from intuitf.evaluator.concurrency import AdaptiveLimit
from intuitf.evaluator.parsing import UnreadableAnswer, parse_answer, strip_reasoning
from intuitf.evaluator.pricing import PriceTable
from intuitf.evaluator.profiles import (
    MAX_OUTPUT_TOKENS,
    STRUCTURED_MODES,
    RequestProfile,
    provider_profile,
    request_profile,
)
from intuitf.evaluator.prompts import (
    SYSTEM_PROMPT,
    response_format,
    user_prompt,
)
from intuitf.evaluator.providers import (
    CUSTOM,
    ProviderPreset,
    Secret,
    config_prices,
    judge_settings,
    judge_timeouts,
    preset,
    redact_url,
    require_api_key,
)
from intuitf.evaluator.responses import (
    _RETRYABLE,
    _error_fields,
    _follow_up,
    _hint_for_status,
    _message,
    _provider_cost,
    _retry_after,
    _short,
    _usage,
)
from intuitf.evaluator.types import Aspect, Choice, Cost, Intent, Verdict, combine_answers

log = logging.getLogger(__name__)

SwapMode = Literal["always", "never", "auto"]

#: Bump when the prompt or the cached payload changes meaning, so old answers are not reused.
PROMPT_VERSION = "intuitf-compare-1"


#: Rough tokens per image part, for a budget estimate before the first priced answer.
_IMAGE_TOKENS_GUESS = 800


@dataclass
class _OrderResult:
    """One call's outcome, in the caller's orientation (first = caller's first image)."""

    per_aspect: dict[str, Choice]
    rationale: dict[str, str] = field(default_factory=dict)
    cost: Cost = field(default_factory=Cost)
    error: str | None = None
    cached: bool = False
    swapped: bool = False
    retries: int = 0


class MLLMJudge:
    """A :class:`~intuitf.evaluator.types.Judge` backed by an OpenAI-compatible multimodal model.

    ``model`` defaults to the provider's default model; for LM Studio, Ollama, vLLM and a server
    given by URL the served model is found with ``GET /v1/models`` when none is named.
    ``provider`` is one of :data:`~intuitf.evaluator.providers.PROVIDERS` (default "openai"
    unless ``base_url`` is given, which works for any compatible server). What is sent (the
    token-limit parameter, temperature, reasoning effort, structured-output mode, images per
    request, requests in flight) follows the provider's and the model family's profile
    (:mod:`intuitf.evaluator.profiles`) and adapts, once per thing, when the server rejects
    something by name; each adaptation is listed in :attr:`adaptations`, logged as a warning and
    passed to ``on_adapt`` (the session records it in run.json).

    ``compose`` lays the images out as separate parts or side by side; ``image_format`` is
    "png" or "jpeg" (quality ``jpeg_quality``) for the candidates; the intent's pictures are
    sized to the candidates and sent as JPEG unless PNG is small. ``structured`` asks for
    JSON-schema output. The API key comes from ``api_key``, the provider's environment variable
    or the config file, and is never shown; credentials in ``base_url`` are used but shown
    redacted (``base_url`` holds the redacted form).

    ``max_output_tokens`` is the answer's token budget (reasoning included; None: ``[judge]`` in
    the config, else by model family) and ``reasoning_effort`` what a reasoning model is asked to
    spend (None: the config, else "low" where the model takes it; "default": none sent).
    ``max_concurrency`` caps the requests in flight (None: the config, else grow from the
    provider's start up to 32, or 4 times the start for a local server); given, the judge starts
    there. ``timeout`` is the most one request may take and ``deadline`` the most one answer may
    take, retries of failed requests included (None: ``[judge]`` in the config file, else 30 s
    and 60 s; time the server asked to wait does not count). ``answer_retries`` is how often an
    unusable answer is asked again (None: as often as a failed request is retried,
    ``max_retries``). ``price`` (USD per 1M input and output tokens) prices this model; with a
    money budget, a model of unknown price is refused unless ``price`` is given or ``unpriced``.
    """

    def __init__(
        self,
        model: str | None = None,
        *,
        base_url: str | None = None,
        api_key: str | None = None,
        provider: str | None = None,
        swap: SwapMode = "always",
        compose: Layout = "parts",
        image_format: ImageFormat = "png",
        jpeg_quality: int = 90,
        max_concurrency: int | None = None,
        timeout: float | None = None,
        max_retries: int = 4,
        cache: VerdictCache | None = None,
        budget: Budget | None = None,
        prices: PriceTable | None = None,
        temperature: float = 0.0,
        structured: bool = True,
        max_output_tokens: int | None = None,
        max_tokens: int | None = None,
        reasoning_effort: str | None = None,
        price: Sequence[float] | None = None,
        unpriced: bool = False,
        max_request_mb: float = 16.0,
        backoff_base: float = 0.5,
        backoff_max: float = 30.0,
        name: str | None = None,
        deadline: float | None = None,
        answer_retries: int | None = None,
        on_adapt: Callable[[dict], None] | None = None,
    ) -> None:
        if swap not in ("always", "never", "auto"):
            raise JudgeError(f"Unknown swap mode {swap!r}.", "Use 'always', 'never' or 'auto'.")
        if compose not in ("parts", "side_by_side"):
            raise JudgeError(f"Unknown image layout {compose!r}.", "Use 'parts' or 'side_by_side'.")
        if image_format not in ("png", "jpeg"):
            raise JudgeError(f"Unknown image format {image_format!r}.", "Use 'png' or 'jpeg'.")
        settings = judge_settings()
        if max_output_tokens is None:
            max_output_tokens = max_tokens or settings.get("max_output_tokens")
        if reasoning_effort is None:
            reasoning_effort = settings.get("reasoning_effort")
        if max_concurrency is None:
            max_concurrency = settings.get("max_concurrency")
        if answer_retries is None:
            answer_retries = max_retries
        if timeout is None or deadline is None:
            default_timeout, default_deadline = judge_timeouts()
            timeout = default_timeout if timeout is None else timeout
            deadline = default_deadline if deadline is None else deadline
        if (
            (max_concurrency is not None and max_concurrency < 1)
            or not timeout > 0
            or not deadline > 0
            or max_retries < 0
            or answer_retries < 0
            or (max_output_tokens is not None and max_output_tokens < 1)
            or not max_request_mb > 0
        ):
            raise JudgeError(
                "max_concurrency and max_output_tokens must be ≥ 1, timeout, deadline and "
                "max_request_mb > 0, max_retries and answer_retries ≥ 0.",
                "Check the judge options.",
            )
        p: ProviderPreset = (
            preset(provider) if provider else (CUSTOM if base_url else preset("openai"))
        )
        self.provider = p.name
        named = model or None
        self.model = named or p.default_model or "default"
        #: Whether the served model is still to be found with GET /v1/models.
        self._discover = named is None and provider_profile(p.name).discover_model
        url = (base_url or p.base_url).rstrip("/") + "/"
        self._url = Secret(url)  # may hold credentials: used, never shown
        self.base_url = redact_url(url)
        self.name = name or f"{p.name}:{self.model}"
        self._api_key = Secret(require_api_key(p, api_key))
        self.swap: SwapMode = swap
        self.compose: Layout = compose
        self.image_format: ImageFormat = image_format
        self.jpeg_quality = int(jpeg_quality)
        self.timeout = float(timeout)
        self.deadline = float(deadline)
        self.max_retries = int(max_retries)
        self.answer_retries = int(answer_retries)
        self.max_request_bytes = int(max_request_mb * 1e6)
        self.cache = cache
        self.budget = budget
        self.prices = prices or PriceTable().with_prices(config_prices())
        given = [float(x) for x in price] if price is not None else None
        self._price: tuple[float, float] | None = None
        if given is not None:
            if len(given) != 2 or min(given) < 0:
                raise JudgeError(
                    f"A model's price is two numbers of 0 or more (got {list(price or [])}).",
                    "Give USD per million input tokens and per million output tokens, e.g. "
                    "--price 0.75,4.50.",
                )
            self._price = (given[0], given[1])
            self.prices = self.prices.with_prices({self.model: self._price})
        self.unpriced = bool(unpriced)
        self.temperature = float(temperature)
        self._effort_option = reasoning_effort
        self._tokens_option = max_output_tokens
        self._structured_option = bool(structured) and p.structured
        self.profile: RequestProfile = self._profile_for(self.model)
        self.backoff_base = float(backoff_base)
        self.backoff_max = float(backoff_max)
        start = self.profile.concurrency
        if max_concurrency is not None:
            start = ceiling = int(max_concurrency)
        else:
            ceiling = 4 * start if self.profile.free else max(32, start)
        self.max_concurrency = int(ceiling)
        self._start_concurrency = int(start)
        #: What the judge changed because the server said so, in order (see the class notes).
        self.adaptations: list[dict] = []
        self.on_adapt = on_adapt
        #: Re-asks with a larger output budget, and requests the server rate-limited.
        self.budget_raises = 0
        self.rate_limited = 0
        #: Running total of everything this judge spent (and served from cache).
        self.cost = Cost()
        self._send_gates: list[Callable[[], None]] = []
        self._client: AsyncOpenAI | None = None
        self._limit: AdaptiveLimit | None = None
        self._lock: asyncio.Lock | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._rng = random.Random()
        self._dearest_usd = 0.0
        #: When an answer last ran out of time (monotonic clock), and why.
        self._gave_up_at: float | None = None
        self._gave_up: str = ""
        #: When the server last answered anything (an answer or an HTTP error; monotonic).
        self._heard_at: float | None = None
        self._check_priced()

    def __repr__(self) -> str:
        return (
            f"MLLMJudge(name={redact_url(self.name)!r}, base_url={self.base_url!r}, swap={self.swap!r}, "
            f"compose={self.compose!r}, max_concurrency={self.max_concurrency})"
        )

    # -- what is sent ---------------------------------------------------------------------------

    def _profile_for(self, model: str) -> RequestProfile:
        return request_profile(
            self.provider,
            model,
            structured=self._structured_option,
            output_tokens=self._tokens_option,
            reasoning_effort=self._effort_option,
        )

    @property
    def structured(self) -> bool:
        """Whether answers are asked for with a JSON schema or as a JSON object."""
        return self.profile.structured != "text"

    @structured.setter
    def structured(self, value: bool) -> None:
        self.profile.structured = "json_schema" if value else "text"

    @property
    def max_tokens(self) -> int:
        """The output budget of the next request (reasoning included)."""
        return self.profile.output_tokens

    @property
    def concurrency(self) -> int:
        """Requests allowed in flight right now (the adaptive limit's width)."""
        return self._limit.width if self._limit is not None else self._start_concurrency

    def _check_priced(self) -> None:
        """A money budget needs a price: refuse a model of unknown price unless told."""
        if (
            self.budget is None
            or self.budget.max_usd is None
            or self.unpriced
            or self.profile.free
            or self.prices.known(self.model)
        ):
            return
        raise JudgeError(
            f"No price is known for the model {self.model!r} ({self.provider}), so a money "
            "budget (--budget-usd) cannot be kept.",
            "Give its price with --price IN,OUT (USD per million input and output tokens), add "
            "it under [prices] in the config file, or run it explicitly unpriced with --unpriced "
            "(its calls then count as free).",
        )

    def _request(self, messages: list[dict], schema: dict, output_tokens: int) -> dict[str, Any]:
        """The chat-completions arguments for one request, as the profile says."""
        prof = self.profile
        kwargs: dict[str, Any] = {
            "model": self.model,
            "messages": messages,
            prof.token_param: int(output_tokens),
        }
        if prof.send_temperature:
            kwargs["temperature"] = self.temperature
        if prof.reasoning_effort:
            kwargs["reasoning_effort"] = prof.reasoning_effort
        if prof.structured == "json_schema":
            kwargs["response_format"] = schema
        elif prof.structured == "json_object":
            kwargs["response_format"] = {"type": "json_object"}
        return kwargs

    def _adapted(self, what: str, change: str, because: str) -> bool:
        """Record that ``what`` was changed (once per thing); False if it already was."""
        if any(a["what"] == what for a in self.adaptations):
            return False
        note = {
            "what": what,
            "change": change,
            "because": self._redact(because)[:200],
            "model": self.model,
            "at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        self.adaptations.append(note)
        self.profile.adapted.append(note)
        log.warning("%s: the server rejected %s; %s from now on.", self.name, what, change)
        if self.on_adapt is not None:
            try:
                self.on_adapt(dict(note))
            except Exception:  # a recorder's trouble must not cost the answer
                log.exception("%s: recording an adaptation failed.", self.name)
        return True

    def _adapt(self, status: int, param: str, code: str, message: str, kwargs: dict) -> bool:
        """Fix the one thing a 400 names (once); True when the request should be sent again."""
        prof = self.profile
        said = f"HTTP {status} {code}: {message}".strip()
        sent = set(kwargs)
        if _settings(kwargs) != _settings(self._request([], {"type": "json_schema"}, 1)):
            # Sent before another request's rejection changed the profile: ask as it now says.
            return True
        both = "max_tokens" in message and "max_completion_tokens" in message
        if "max_tokens" in sent and (param == "max_tokens" or both):
            prof.token_param = "max_completion_tokens"
            return self._adapted("max_tokens", "sending max_completion_tokens instead", said)
        if "max_completion_tokens" in sent and (
            param == "max_completion_tokens" or "max_completion_tokens" in message
        ):
            prof.token_param = "max_tokens"
            return self._adapted("max_completion_tokens", "sending max_tokens instead", said)
        if "temperature" in sent and (param == "temperature" or "temperature" in message):
            prof.send_temperature = False
            return self._adapted("temperature", "sending no temperature (the default)", said)
        if "reasoning_effort" in sent and ("reasoning" in param or "reasoning" in message):
            listed = re.findall(r"'([a-z]+)'", message.split("supported values", 1)[-1])
            listed = [v for v in _EFFORTS if v in listed and v != prof.reasoning_effort]
            if listed:
                prof.reasoning_effort = listed[0]
                return self._adapted(
                    "reasoning_effort", f"sending reasoning_effort={listed[0]}", said
                )
            prof.reasoning_effort = None
            return self._adapted("reasoning_effort", "sending no reasoning_effort", said)
        if "response_format" in sent and (
            "response_format" in param
            or any(w in message for w in ("response_format", "json_schema", "json schema"))
        ):
            modes = STRUCTURED_MODES
            nxt = modes[min(len(modes) - 1, modes.index(prof.structured) + 1)]
            if nxt == "json_object" and "json_schema" not in message:
                nxt = "text"  # response_format itself is not taken, not just the schema
            what = f"response_format={prof.structured}"
            prof.structured = nxt
            change = "asking for JSON in plain text" if nxt == "text" else f"asking for {nxt}"
            return self._adapted(what, change, said)
        m = re.search(r"(?:at most|only|maximum of|limit (?:is|of)) (\d+) images?", message)
        if m:
            prof.max_images = max(1, int(m.group(1)))
            self._adapted("images per request", f"sending at most {prof.max_images}", said)
            raise _Rebuild
        return False

    # -- plumbing -----------------------------------------------------------------------------

    def _session(self) -> tuple[AsyncOpenAI, AdaptiveLimit]:
        """The client and concurrency limit of the running event loop (both are bound to it)."""
        loop = asyncio.get_running_loop()
        if self._loop is not loop or self._client is None or self._limit is None:
            self._client = AsyncOpenAI(
                api_key=self._api_key.reveal(),
                base_url=self._url.reveal(),
                max_retries=0,
                timeout=self.timeout,
            )
            start = self._limit.width if self._limit is not None else self._start_concurrency
            self._limit = AdaptiveLimit(start, self.max_concurrency)
            self._lock = asyncio.Lock()
            self._loop = loop
        return self._client, self._limit

    async def _find_model(self, client: AsyncOpenAI) -> None:
        """The served model, from ``GET /v1/models`` (once; the first caller asks, others wait)."""
        if not self._discover or self._lock is None:
            return
        async with self._lock:
            if not self._discover:
                return
            try:
                page = await client.models.list(timeout=min(self.timeout, 10.0))
                ids = [str(m.id) for m in page.data]
            except (openai.APIError, ValueError) as exc:
                log.info("%s: could not list the served models (%s).", self.name, exc)
                ids = []
            self._discover = False
            chosen = _pick_model(ids, self.model)
            if chosen and chosen != self.model:
                log.warning(
                    "%s: using the served model %r (found with GET /v1/models).", self.name, chosen
                )
                self.model = chosen
                adapted = self.profile.adapted
                self.profile = self._profile_for(chosen)
                self.profile.adapted = adapted
                if self._price is not None:
                    self.prices = self.prices.with_prices({chosen: self._price})
                self._check_priced()

    async def aclose(self) -> None:
        """Close the HTTP client (optional; it is also dropped with the judge)."""
        if self._client is not None:
            await self._client.close()
            self._client = None

    def _redact(self, text: str) -> str:
        key = self._api_key.reveal()
        if key and len(key) >= 4:
            text = text.replace(key, "***")
        return redact_url(text) or ""

    def _backoff(self, attempt: int, retry_after: float | None) -> float:
        if retry_after is not None:
            # Honour the server's wish, plus a little jitter so waiting clients do not stampede.
            return min(retry_after, max(self.backoff_max, 60.0)) * (1.0 + 0.1 * self._rng.random())
        d = min(self.backoff_max, self.backoff_base * 2**attempt)
        return d / 2 + self._rng.uniform(0, d / 2)

    # -- one call -----------------------------------------------------------------------------

    def _estimate_usd(self, prompt: str, n_images: int) -> float:
        """The next call's price: the dearest seen so far, else a guess from the prompt size."""
        if self._dearest_usd > 0:
            return self._dearest_usd
        tokens_in = len(prompt) // 4 + n_images * _IMAGE_TOKENS_GUESS
        # A reasoning model's thoughts are billed as output too.
        tokens_out = 300 + (self.profile.output_tokens // 4 if self.profile.thinking else 0)
        return self.prices.cost(self.model, tokens_in, tokens_out)

    def _no_answer(self, message: str) -> JudgeError:
        return JudgeError(
            message,
            "Check that the server is running and answering (one that accepts connections but "
            "never answers looks like this; a slow model needs a longer --request-timeout or "
            "--answer-deadline, a busy one a lower --max-concurrency). Every answer received so "
            "far is kept in the verdict store: continue with `intuitf optimize --resume RUN`.",
        )

    def _billing(self, status: int, code: str, message: str) -> BudgetExhausted:
        return BudgetExhausted(
            f"The {self.provider} account has no credit or quota left for {self.model} "
            f"(HTTP {status}{', ' + code if code else ''}): {self._redact(message)[:160]}",
            "Add credit or raise the quota with the provider (or use another model); everything "
            "judged so far is kept: continue with `intuitf optimize --resume RUN`.",
        )

    def add_send_gate(self, gate: Callable[[], None]) -> None:
        """Call ``gate`` right before each request leaves, once its turn has come: an
        exception it raises stops the request unsent (nothing paid, its budget freed). A
        batch worker stops this way the moment its driver is gone, including requests that
        were queued for a turn when it went."""
        self._send_gates.append(gate)

    async def _complete(
        self, messages: list[dict], schema: dict, estimate: float, output_tokens: int
    ) -> tuple[Any, Cost]:
        """One answered call (with retries); JudgeError when the server never answers.

        Raises :class:`_Rebuild` when the server's answer changes how the question must be
        put (fewer images per request).
        """
        client, limit = self._session()
        await self._find_model(client)
        cost = Cost()
        last = "no attempt"
        attempt = 0
        limited = 0  # rate-limited tries of this answer (counted apart from failures)
        started: float | None = None  # when the first attempt got its turn
        deadline_hit = False
        resent = 0  # sent again because a 400 was fixed (bounded: a fix must not loop)
        while attempt <= self.max_retries:
            if self._gave_up_at is not None and started is None:
                if time.monotonic() - self._gave_up_at < self.deadline:
                    # Another answer just ran out of time on this server: do not queue behind it.
                    self.cost += cost
                    raise self._no_answer(self._gave_up)
                self._gave_up_at = None
            kwargs = self._request(messages, schema, output_tokens)
            reserved = self.budget.reserve(estimate) if self.budget is not None else 0.0
            row = None
            t0 = time.perf_counter()
            try:
                async with limit.slot():
                    now = time.monotonic()
                    if started is None:
                        started = now
                    left = self.deadline - (now - started)
                    if left <= 0:
                        deadline_hit = True
                        raise _OutOfTime
                    kwargs["timeout"] = min(self.timeout, left)
                    for gate in self._send_gates:
                        gate()
                    if self.cache is not None:
                        row = self.cache.begin_spend(self.name, reserved)
                    t0 = time.perf_counter()
                    resp = await client.chat.completions.create(**kwargs)
            except _OutOfTime:
                if self.budget is not None:
                    self.budget.release(reserved)
                break
            except RunCancelled:  # a send gate stopped it before it left
                if self.budget is not None:
                    self.budget.release(reserved)
                self.cost += cost
                raise
            except openai.APIStatusError as exc:
                self._unpaid(reserved, row)
                self._heard_at = time.monotonic()  # alive, if unhappy
                cost.seconds += time.perf_counter() - t0
                status = exc.status_code
                param, code, message = _error_fields(exc)
                if status == 402 or "insufficient_quota" in (code + " " + message):
                    self.cost += cost
                    raise self._billing(status, code, message) from None
                if (
                    status in (400, 404, 415, 422)
                    and resent < _MAX_RESENDS
                    and self._adapt(status, param, code, message, kwargs)
                ):
                    resent += 1
                    continue  # one thing fixed: the same question, asked right
                cost.failed_calls += 1
                if status not in _RETRYABLE:
                    self.cost += cost
                    raise JudgeError(
                        f"The model server for {self.name} rejected the request (HTTP {status}): "
                        f"{self._redact(_short(exc))}",
                        _hint_for_status(status, self.provider),
                    ) from None
                last = f"HTTP {status}"
                hint = _retry_after(exc.response, getattr(exc, "body", None))
                overloaded = status in (429, 503, 529)
                wait = self._backoff(limited if overloaded else attempt, hint)
                if overloaded:
                    limit.overloaded()
                    if status == 429:
                        self.rate_limited += 1
                    if hint is not None:
                        limit.pause(wait)
                    limited += 1
                    if limited <= _RATE_LIMITED_TRIES:
                        # The server is alive and asked us to wait: not a failure of this
                        # answer, and the wait does not count against its deadline.
                        if started is not None:
                            started += wait
                        log.info("%s: rate-limited (%s); waiting %.2f s.", self.name, last, wait)
                        await asyncio.sleep(wait)
                        continue
            except (openai.APITimeoutError, openai.APIConnectionError) as exc:
                self._unpaid(reserved, row)
                cost.seconds += time.perf_counter() - t0
                cost.failed_calls += 1
                timed_out = isinstance(exc, openai.APITimeoutError)
                if timed_out:
                    limit.overloaded()
                last = (
                    f"timed out after {kwargs.get('timeout', self.timeout):.3g} s"
                    if timed_out
                    else "connection failed"
                )
                wait = self._backoff(attempt, None)
            else:
                took = time.perf_counter() - t0
                cost.seconds += took
                if took < self.timeout / 2:
                    limit.answered()
                tin, tout = _usage(resp)
                reported = _provider_cost(resp)
                usd = reported if reported is not None else self.prices.cost(self.model, tin, tout)
                if self.budget is not None:
                    self.budget.settle(reserved, usd)
                if row is not None:
                    self.cache.settle_spend(row, tin, tout, usd)  # type: ignore[union-attr]
                cost.calls += 1
                cost.input_tokens += tin
                cost.output_tokens += tout
                cost.usd += usd
                self._dearest_usd = max(self._dearest_usd, usd)
                self._gave_up_at = None
                self._heard_at = time.monotonic()
                return resp, cost
            attempt += 1
            if attempt > self.max_retries:
                break
            if started is not None and time.monotonic() + wait - started >= self.deadline:
                deadline_hit = True
                break
            log.warning(
                "%s: call failed (%s), retry %d of %d in %.2f s.",
                self.name,
                last,
                attempt,
                self.max_retries,
                wait,
            )
            await asyncio.sleep(wait)
        self.cost += cost
        tries = f"{attempt} attempt{'s' if attempt != 1 else ''}"
        if deadline_hit:
            message = (
                f"The model server for {self.name} at {self.base_url} gave no answer within "
                f"{self.deadline:g} s ({tries}; last: {last})."
            )
            now = time.monotonic()
            if self._heard_at is None or now - self._heard_at >= self.deadline:
                # Nothing at all from the server for a whole deadline: it is down, so the
                # next answers fail at once. One answer unlucky with hangs while the server
                # answers others does not stop them.
                self._gave_up_at, self._gave_up = now, message
        else:
            message = (
                f"The model server for {self.name} at {self.base_url} gave no answer after "
                f"{tries} (last: {last})."
            )
        raise self._no_answer(message)

    def _unpaid(self, reserved: float, row: int | None) -> None:
        """A request got no answer: give its budget back and drop its spend record."""
        if self.budget is not None:
            self.budget.release(reserved)
        if row is not None and self.cache is not None:
            self.cache.cancel_spend(row)

    async def _ask(
        self,
        shown_first: np.ndarray,
        shown_second: np.ndarray,
        aspects: Sequence[Aspect],
        intent: Intent,
        swapped: bool,
    ) -> _OrderResult:
        """Ask about the images in the order shown; report in the caller's orientation."""
        layout = self._layout_for(intent)
        prompt = user_prompt(aspects, intent, layout)
        images = self._images(shown_first, shown_second, intent, layout)
        key = request_key(
            self.name,
            [
                PROMPT_VERSION,
                SYSTEM_PROMPT,
                prompt,
                f"{layout}|{self.image_format}|{self.jpeg_quality}|t={self.temperature}",
                intent.fingerprint(),
                *(x for im in images for x in (im.label, im.image)),
            ],
        )

        def orient(per: dict[str, Choice]) -> dict[str, Choice]:
            return {k: (c.swapped() if swapped else c) for k, c in per.items()}

        if self.cache is not None:
            hit = self.cache.get(key)
            if hit is not None:
                return _OrderResult(
                    per_aspect=orient({k: Choice(v) for k, v in hit["per_aspect"].items()}),
                    rationale=dict(hit.get("rationale", {})),
                    cost=Cost(cached_calls=1),
                    cached=True,
                    swapped=swapped,
                )
        messages = await self._messages(prompt, images)
        estimate = self._estimate_usd(prompt, len(images))
        schema = response_format(aspects, intent)
        cost = Cost()
        conversation = messages
        retries = refusals = 0
        output_tokens = self.profile.output_tokens
        while True:
            try:
                resp, paid = await self._complete(conversation, schema, estimate, output_tokens)
            except _Rebuild:
                # The server takes fewer images: the same question, laid out anew.
                layout = self._layout_for(intent)
                prompt = user_prompt(aspects, intent, layout)
                images = self._images(shown_first, shown_second, intent, layout)
                conversation = messages = await self._messages(prompt, images)
                continue
            cost += paid
            text, refusal, finish = _message(resp)
            try:
                if refusal:
                    raise UnreadableAnswer("refusal", refusal)
                if finish == "content_filter" and not text:
                    raise UnreadableAnswer("refusal", "blocked by the server's content filter")
                parsed = parse_answer(text, aspects)
                break
            except UnreadableAnswer as exc:
                reason = "truncated" if finish == "length" else exc.reason
                msg = f"{reason}: {self._redact(exc.detail)[:160]}"
                refusals += reason == "refusal"
                if retries >= self.answer_retries or refusals > 1:
                    log.warning(
                        "%s: unusable answer counted as a tie after %d re-ask(s) (%s).",
                        self.name,
                        retries,
                        msg,
                    )
                    return _OrderResult(
                        per_aspect={a.key: Choice.TIE for a in aspects},
                        cost=cost,
                        error=msg,
                        swapped=swapped,
                        retries=retries,
                    )
                retries += 1
                if reason == "truncated" and not strip_reasoning(text or ""):
                    # The budget went on reasoning: a larger one, not "keep it short".
                    output_tokens = min(MAX_OUTPUT_TOKENS, 2 * output_tokens)
                    self.budget_raises += 1
                    if output_tokens > self.profile.output_tokens:
                        self.profile.output_tokens = output_tokens
                        log.info(
                            "%s: the answer's budget went on reasoning; %d tokens from now on.",
                            self.name,
                            output_tokens,
                        )
                log.info("%s: unusable answer (%s); asking again.", self.name, msg)
                conversation = _follow_up(messages, reason, text or refusal)
        rationale = dict(parsed.rationale)
        if parsed.reference_description:
            rationale["reference_description"] = parsed.reference_description
        if self.cache is not None:
            self.cache.put(
                key,
                self.name,
                {
                    "per_aspect": {k: c.value for k, c in parsed.per_aspect.items()},
                    "rationale": rationale,
                    "missing": parsed.missing,
                    "input_tokens": cost.input_tokens,
                    "output_tokens": cost.output_tokens,
                    "usd": cost.usd,
                },
            )
        return _OrderResult(
            orient(parsed.per_aspect), rationale, cost, swapped=swapped, retries=retries
        )

    def _layout_for(self, intent: Intent) -> Layout:
        """The judge's layout, or side by side when the server takes too few images for parts."""
        limit = self.profile.max_images
        if limit is not None and self.compose == "parts":
            if len(intent_images(intent)) + 2 > limit:
                return "side_by_side"
        return self.compose

    def _images(
        self, first: np.ndarray, second: np.ndarray, intent: Intent, layout: Layout
    ) -> list[LabelledImage]:
        images = comparison_images(first, second, intent, layout)
        limit = self.profile.max_images
        if limit is not None and len(images) > limit:
            raise JudgeError(
                f"The model server for {self.name} takes {limit} image(s) per request; this "
                f"comparison needs {len(images)} (the intent's pictures and the candidates).",
                "Let the server take more images per request (vLLM: --limit-mm-per-prompt "
                "'{\"image\": 4}'), or judge with a text intent.",
            )
        return images

    async def _messages(self, prompt: str, images: list[LabelledImage]) -> list[dict]:
        # Encoding takes milliseconds per image; a worker thread keeps the event loop (and the
        # other comparisons' HTTP traffic) moving meanwhile.
        parts = await asyncio.to_thread(
            content_parts, images, self.image_format, self.jpeg_quality, self.max_request_bytes
        )
        return [
            {"role": "system", "content": SYSTEM_PROMPT},
            {"role": "user", "content": [{"type": "text", "text": prompt}, *parts]},
        ]

    # -- the Judge protocol -------------------------------------------------------------------

    async def compare(
        self,
        first: np.ndarray,
        second: np.ndarray,
        aspects: Sequence[Aspect],
        intent: Intent,
    ) -> Verdict:
        """Compare ``first`` and ``second`` (uint8 RGB) on ``aspects`` under ``intent``."""
        aspects = list(aspects)
        if not aspects:
            raise JudgeError("No aspects to judge on.", "Pass at least one Aspect.")
        if self.swap == "never":
            results = await self._gather([(first, second, False)], aspects, intent)
        elif self.swap == "always":
            results = await self._gather(
                [(first, second, False), (second, first, True)], aspects, intent
            )
        else:
            swapped = _content_order(first, second)
            order = (second, first, True) if swapped else (first, second, False)
            results = await self._gather([order], aspects, intent)
            r = results[0]
            if r.error is not None or _combine([r], aspects)[0] is Choice.TIE:
                other = (first, second, False) if swapped else (second, first, True)
                results += await self._gather([other], aspects, intent)
        return self._verdict(results, aspects)

    async def _gather(
        self, orders: list[tuple], aspects: list[Aspect], intent: Intent
    ) -> list[_OrderResult]:
        # Let every call finish (paid answers reach the cache) before an error propagates.
        out = await asyncio.gather(
            *(self._ask(a, b, aspects, intent, s) for a, b, s in orders), return_exceptions=True
        )
        for r in out:
            if isinstance(r, _OrderResult):
                self.cost += r.cost
        for r in out:
            if isinstance(r, BaseException):
                raise r
        return list(out)  # type: ignore[arg-type]

    def _verdict(self, results: list[_OrderResult], aspects: list[Aspect]) -> Verdict:
        cost = Cost()
        for r in results:
            cost += r.cost
        valid = [r for r in results if r.error is None]
        retries = sum(r.retries for r in results)
        if not valid:
            return Verdict(
                per_aspect={a.key: Choice.TIE for a in aspects},
                overall=Choice.TIE,
                p_first=0.5,
                cost=cost,
                error="; ".join(r.error or "" for r in results),
                retries=retries,
            )
        overall, p, per = _combine(valid, aspects)
        rationale: dict[str, str] = {}
        for k in sorted({k for r in valid for k in r.rationale}):
            texts = [(r.swapped, r.rationale[k]) for r in valid if r.rationale.get(k)]
            # Analyses speak of "Image 1/2" as shown; say which order each one saw.
            rationale[k] = " | ".join(
                f"({'swapped' if sw else 'as given'}) {t}" if len(texts) > 1 else t
                for sw, t in texts
            )
        return Verdict(
            per_aspect=per,
            overall=overall,
            p_first=p,
            cost=cost,
            rationale=rationale,
            cached=all(r.cached for r in results),
            retries=retries,
        )


class _OutOfTime(Exception):
    """The answer's deadline passed before another attempt could start."""


#: How often one question is sent again after fixing what a 400 named. Each adaptable thing is
#: fixed once, so a well-behaved server needs at most a handful; a server that keeps rejecting
#: a request the judge believes fixed (or a question built in a form the profile does not
#: describe) then fails as that request's error instead of being asked until the deadline.
_MAX_RESENDS = 6


def _settings(kwargs: dict) -> dict:
    """A request's parameters apart from its content and size (what an adaptation changes)."""
    out = {k: v for k, v in kwargs.items() if k not in ("messages", "timeout", "response_format")}
    for k in ("max_tokens", "max_completion_tokens"):
        if k in out:
            out[k] = "set"
    rf = kwargs.get("response_format")
    out["response_format"] = rf.get("type") if isinstance(rf, dict) else None
    return out


class _Rebuild(Exception):
    """The server takes the question only in another form (fewer images): build it again."""


#: Reasoning efforts from least to most, to pick the cheapest a server lists as supported.
_EFFORTS = ("none", "minimal", "low", "medium", "high", "xhigh")

#: Rate-limited tries of one answer that are waited out without counting as failures.
_RATE_LIMITED_TRIES = 12

#: Names that mark a model as one that sees images, to choose among several served models.
_VISION = re.compile(r"(vl|vision|llava|pixtral|gemma-?3|minicpm-v|moondream|qwen.*omni)", re.I)


def _pick_model(ids: list[str], wanted: str) -> str | None:
    """The model to use among the served ``ids``: the wanted one when served, the only one,
    else the first that looks like a vision model, else the first."""
    if not ids:
        return None
    if wanted in ids:
        return wanted
    if len(ids) == 1:
        return ids[0]
    seeing = [i for i in ids if _VISION.search(i)]
    return (seeing or ids)[0]


def _combine(
    results: list[_OrderResult], aspects: list[Aspect]
) -> tuple[Choice, float, dict[str, Choice]]:
    """The answers of one or both orders, combined by the one rule (``combine_answers``)."""
    return combine_answers([r.per_aspect for r in results], aspects)


def _content_order(first: np.ndarray, second: np.ndarray) -> bool:
    """Whether "auto" shows ``second`` first: decided by content, the same for (a, b) and (b, a)."""
    da = hashlib.sha256(np.ascontiguousarray(first).tobytes()).digest()
    db = hashlib.sha256(np.ascontiguousarray(second).tobytes()).digest()
    return db < da
