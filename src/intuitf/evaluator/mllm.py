"""MLLMJudge: a multimodal model compares two renderings over the OpenAI chat-completions protocol.

One ``AsyncOpenAI`` client per judge (per event loop) reaches OpenAI, Gemini, Ollama, vLLM, LM
Studio, OpenRouter or any compatible server. The SDK's own retries are off; this module retries
with exponential backoff and jitter, honouring ``Retry-After``.

**Unusable answers are asked again.** An answer with no readable choice (unparseable or cut
off) is followed up with a corrective message ("answer only with the JSON object ..."), a
refusal with a short explanation of the task (once: a second refusal is final), and a "blind"
answer (the model says it cannot see the images) by sending the question again; at most
``answer_retries`` times per answer (by default the retry budget, ``max_retries``). Only when every try was unusable does the comparison become
a *logged tie* (``Verdict.error`` set, the verdict *undecided*, not cached). ``Verdict.retries``
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
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import openai
from openai import AsyncOpenAI

from intuitf.errors import JudgeError
from intuitf.evaluator.budget import Budget
from intuitf.evaluator.cache import VerdictCache, request_key
from intuitf.evaluator.compose import ImageFormat, Layout, comparison_images, content_parts
from intuitf.evaluator.parsing import UnreadableAnswer, parse_answer
from intuitf.evaluator.pricing import PriceTable
from intuitf.evaluator.prompts import (
    SYSTEM_PROMPT,
    response_format,
    user_prompt,
)
from intuitf.evaluator.providers import (
    CUSTOM,
    ProviderPreset,
    Secret,
    judge_timeouts,
    preset,
    redact_url,
    require_api_key,
)
from intuitf.evaluator.responses import (
    _RETRYABLE,
    _follow_up,
    _hint_for_status,
    _message,
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

    ``model`` defaults to the provider's default model; ``provider`` is one of
    :data:`~intuitf.evaluator.providers.PROVIDERS` (default "openai" unless ``base_url`` is given,
    which works for any compatible server). ``compose`` lays the images out as separate parts or
    side by side; ``image_format`` is "png" or "jpeg" (quality ``jpeg_quality``). ``structured``
    asks for JSON-schema output and falls back to plain text, for the rest of this judge's life,
    when the server rejects it. The API key comes from ``api_key``, the provider's environment
    variable or the config file, and is never shown; credentials in ``base_url`` are used but
    shown redacted (``base_url`` holds the redacted form).

    ``timeout`` is the most one request may take and ``deadline`` the most one answer may take,
    retries of failed requests included (None: ``[judge]`` in the config file, else 30 s and
    60 s). ``answer_retries`` is how often an unusable answer is asked again (None: as often as
    a failed request is retried, ``max_retries``).
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
        max_concurrency: int = 32,
        timeout: float | None = None,
        max_retries: int = 4,
        cache: VerdictCache | None = None,
        budget: Budget | None = None,
        prices: PriceTable | None = None,
        temperature: float = 0.0,
        structured: bool = True,
        max_tokens: int = 2048,
        backoff_base: float = 0.5,
        backoff_max: float = 30.0,
        name: str | None = None,
        deadline: float | None = None,
        answer_retries: int | None = None,
    ) -> None:
        if swap not in ("always", "never", "auto"):
            raise JudgeError(f"Unknown swap mode {swap!r}.", "Use 'always', 'never' or 'auto'.")
        if compose not in ("parts", "side_by_side"):
            raise JudgeError(f"Unknown image layout {compose!r}.", "Use 'parts' or 'side_by_side'.")
        if image_format not in ("png", "jpeg"):
            raise JudgeError(f"Unknown image format {image_format!r}.", "Use 'png' or 'jpeg'.")
        if answer_retries is None:
            answer_retries = max_retries
        if timeout is None or deadline is None:
            default_timeout, default_deadline = judge_timeouts()
            timeout = default_timeout if timeout is None else timeout
            deadline = default_deadline if deadline is None else deadline
        if (
            max_concurrency < 1
            or not timeout > 0
            or not deadline > 0
            or max_retries < 0
            or answer_retries < 0
        ):
            raise JudgeError(
                "max_concurrency must be ≥ 1, timeout and deadline > 0, max_retries and "
                "answer_retries ≥ 0.",
                "Check the judge options.",
            )
        p: ProviderPreset = (
            preset(provider) if provider else (CUSTOM if base_url else preset("openai"))
        )
        self.provider = p.name
        self.model = model or p.default_model
        url = (base_url or p.base_url).rstrip("/") + "/"
        self._url = Secret(url)  # may hold credentials: used, never shown
        self.base_url = redact_url(url)
        self.name = name or f"{p.name}:{self.model}"
        self._api_key = Secret(require_api_key(p, api_key))
        self.swap: SwapMode = swap
        self.compose: Layout = compose
        self.image_format: ImageFormat = image_format
        self.jpeg_quality = int(jpeg_quality)
        self.max_concurrency = int(max_concurrency)
        self.timeout = float(timeout)
        self.deadline = float(deadline)
        self.max_retries = int(max_retries)
        self.answer_retries = int(answer_retries)
        self.cache = cache
        self.budget = budget
        self.prices = prices or PriceTable()
        self.temperature = float(temperature)
        self.max_tokens = int(max_tokens)
        self.backoff_base = float(backoff_base)
        self.backoff_max = float(backoff_max)
        self.structured = bool(structured) and p.structured
        #: Running total of everything this judge spent (and served from cache).
        self.cost = Cost()
        self._client: AsyncOpenAI | None = None
        self._sem: asyncio.Semaphore | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._rng = random.Random()
        self._dearest_usd = 0.0
        #: When an answer last ran out of time (monotonic clock), and why.
        self._gave_up_at: float | None = None
        self._gave_up: str = ""

    def __repr__(self) -> str:
        return (
            f"MLLMJudge(name={redact_url(self.name)!r}, base_url={self.base_url!r}, swap={self.swap!r}, "
            f"compose={self.compose!r}, max_concurrency={self.max_concurrency})"
        )

    # -- plumbing -----------------------------------------------------------------------------

    def _session(self) -> tuple[AsyncOpenAI, asyncio.Semaphore]:
        """The client and semaphore of the running event loop (both are bound to a loop)."""
        loop = asyncio.get_running_loop()
        if self._loop is not loop or self._client is None or self._sem is None:
            self._client = AsyncOpenAI(
                api_key=self._api_key.reveal(),
                base_url=self._url.reveal(),
                max_retries=0,
                timeout=self.timeout,
            )
            self._sem = asyncio.Semaphore(self.max_concurrency)
            self._loop = loop
        return self._client, self._sem

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
        return self.prices.cost(self.model, tokens_in, 300)

    def _no_answer(self, message: str) -> JudgeError:
        return JudgeError(
            message,
            "Check that the server is running and answering (one that accepts connections but "
            "never answers looks like this; a slow model needs a longer --request-timeout or "
            "--answer-deadline). Every answer received so far is kept in the verdict store: "
            "continue with `intuitf optimize --resume RUN`.",
        )

    async def _complete(
        self, messages: list[dict], schema: dict, estimate: float
    ) -> tuple[Any, Cost]:
        """One answered call (with retries); JudgeError when the server never answers."""
        client, sem = self._session()
        cost = Cost()
        last = "no attempt"
        attempt = 0
        started: float | None = None  # when the first attempt got its turn
        deadline_hit = False
        while attempt <= self.max_retries:
            if self._gave_up_at is not None and started is None:
                if time.monotonic() - self._gave_up_at < self.deadline:
                    # Another answer just ran out of time on this server: do not queue behind it.
                    self.cost += cost
                    raise self._no_answer(self._gave_up)
                self._gave_up_at = None
            kwargs: dict[str, Any] = {
                "model": self.model,
                "messages": messages,
                "temperature": self.temperature,
                "max_tokens": self.max_tokens,
            }
            structured = self.structured
            if structured:
                kwargs["response_format"] = schema
            reserved = self.budget.reserve(estimate) if self.budget is not None else 0.0
            row = None
            t0 = time.perf_counter()
            try:
                async with sem:
                    now = time.monotonic()
                    if started is None:
                        started = now
                    left = self.deadline - (now - started)
                    if left <= 0:
                        deadline_hit = True
                        raise _OutOfTime
                    kwargs["timeout"] = min(self.timeout, left)
                    if self.cache is not None:
                        row = self.cache.begin_spend(self.name, reserved)
                    t0 = time.perf_counter()
                    resp = await client.chat.completions.create(**kwargs)
            except _OutOfTime:
                if self.budget is not None:
                    self.budget.release(reserved)
                break
            except openai.APIStatusError as exc:
                self._unpaid(reserved, row)
                cost.seconds += time.perf_counter() - t0
                status = exc.status_code
                if structured and status in (400, 415, 422):
                    # The server does not take a JSON schema: ask in plain text from now on.
                    log.info(
                        "%s: structured output rejected (HTTP %s); using plain text.",
                        self.name,
                        status,
                    )
                    self.structured = False
                    continue
                cost.failed_calls += 1
                if status not in _RETRYABLE:
                    self.cost += cost
                    raise JudgeError(
                        f"The model server for {self.name} rejected the request (HTTP {status}): "
                        f"{self._redact(_short(exc))}",
                        _hint_for_status(status, self.provider),
                    ) from None
                last = f"HTTP {status}"
                wait = self._backoff(attempt, _retry_after(exc.response))
            except (openai.APITimeoutError, openai.APIConnectionError) as exc:
                self._unpaid(reserved, row)
                cost.seconds += time.perf_counter() - t0
                cost.failed_calls += 1
                last = (
                    f"timed out after {kwargs.get('timeout', self.timeout):.3g} s"
                    if isinstance(exc, openai.APITimeoutError)
                    else "connection failed"
                )
                wait = self._backoff(attempt, None)
            else:
                cost.seconds += time.perf_counter() - t0
                tin, tout = _usage(resp)
                usd = self.prices.cost(self.model, tin, tout)
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
            self._gave_up_at, self._gave_up = time.monotonic(), message
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
        prompt = user_prompt(aspects, intent, self.compose)
        images = comparison_images(shown_first, shown_second, intent, self.compose)
        key = request_key(
            self.name,
            [
                PROMPT_VERSION,
                SYSTEM_PROMPT,
                prompt,
                f"{self.compose}|{self.image_format}|{self.jpeg_quality}|t={self.temperature}",
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
        # Encoding takes milliseconds per image; a worker thread keeps the event loop (and the
        # other comparisons' HTTP traffic) moving meanwhile.
        parts = await asyncio.to_thread(content_parts, images, self.image_format, self.jpeg_quality)
        messages = [
            {"role": "system", "content": SYSTEM_PROMPT},
            {"role": "user", "content": [{"type": "text", "text": prompt}, *parts]},
        ]
        estimate = self._estimate_usd(prompt, len(images))
        schema = response_format(aspects, intent)
        cost = Cost()
        conversation = messages
        retries = refusals = 0
        while True:
            resp, paid = await self._complete(conversation, schema, estimate)
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
