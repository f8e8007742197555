"""Reading a model server's answers: token usage, the message, retry delays, error hints, and
the corrective follow-up for an answer that could not be used."""

from __future__ import annotations

import email.utils
import re
import time
from typing import Any

import openai

from intuitf.evaluator.parsing import content_text, strip_reasoning
from intuitf.evaluator.prompts import (
    FOLLOW_UP_REFUSAL,
    FOLLOW_UP_TRUNCATED,
    FOLLOW_UP_UNREADABLE,
)

#: HTTP statuses worth retrying: timeouts, conflicts, rate limits, server trouble.
_RETRYABLE = {408, 409, 425, 429, 500, 502, 503, 504, 520, 522, 524, 529}


def _follow_up(messages: list[dict], reason: str, answer: str | None) -> list[dict]:
    """The conversation to send after an unusable answer (see the module notes).

    An empty assistant turn is never sent (Gemini rejects it: "parts must not be empty"): an
    answer with nothing but reasoning is followed by the question alone, and an empty answer
    cut off by the output budget is asked again as it was (with a larger budget).
    """
    if reason == "blind":
        return messages  # the images may not have come through: send them again
    said = strip_reasoning(answer or "")[:4000]
    if not said.strip():
        if reason == "truncated":
            return messages
        reason_text = FOLLOW_UP_REFUSAL if reason == "refusal" else FOLLOW_UP_UNREADABLE
        return [*messages, {"role": "user", "content": reason_text}]
    text = {
        "refusal": FOLLOW_UP_REFUSAL,
        "truncated": FOLLOW_UP_TRUNCATED,
    }.get(reason, FOLLOW_UP_UNREADABLE)
    return [
        *messages,
        {"role": "assistant", "content": said},
        {"role": "user", "content": text},
    ]


def _usage(resp: Any) -> tuple[int, int]:
    """(input tokens, output tokens billed) of a completion.

    Reasoning tokens are billed as output. OpenAI counts them inside ``completion_tokens``;
    servers that report them apart (``total_tokens`` larger than prompt plus completion, as
    Gemini's thoughts) have the difference added.
    """
    u = getattr(resp, "usage", None)
    if u is None:
        return 0, 0
    tin = int(getattr(u, "prompt_tokens", 0) or 0)
    tout = int(getattr(u, "completion_tokens", 0) or 0)
    total = int(getattr(u, "total_tokens", 0) or 0)
    if total > tin + tout:
        tout = total - tin
    return tin, tout


def _provider_cost(resp: Any) -> float | None:
    """The price the server itself reports for a call (OpenRouter's ``usage.cost``), if any."""
    u = getattr(resp, "usage", None)
    cost = getattr(u, "cost", None) if u is not None else None
    if cost is None and u is not None:
        extra = getattr(u, "model_extra", None) or {}
        cost = extra.get("cost")
    try:
        value = float(cost) if cost is not None else None
    except (TypeError, ValueError):
        return None
    return value if value is not None and value >= 0 else None


def _message(resp: Any) -> tuple[str | None, str | None, str | None]:
    """(answer text, refusal, finish reason) of a completion. Content given as a list of parts
    is joined from its text parts; reasoning fields (``reasoning_content``, ``reasoning``) are
    not the answer and are left out."""
    choices = getattr(resp, "choices", None) or []
    if not choices:
        return None, None, None
    msg = choices[0].message
    content = content_text(getattr(msg, "content", None))
    return content, getattr(msg, "refusal", None), choices[0].finish_reason


_DURATION = re.compile(r"(?P<n>\d+(?:\.\d+)?)(?P<unit>ms|h|m|s)")


def _duration(text: str) -> float | None:
    """Seconds in "1.5", "20ms", "6m0s", "37s" or "1h2m" (rate-limit headers and retryDelay)."""
    text = str(text).strip()
    try:
        return max(0.0, float(text))
    except ValueError:
        pass
    parts = list(_DURATION.finditer(text))
    if not parts or "".join(m.group(0) for m in parts) != text:
        return None
    scale = {"ms": 0.001, "s": 1.0, "m": 60.0, "h": 3600.0}
    return sum(float(m.group("n")) * scale[m.group("unit")] for m in parts)


def _retry_after(response: Any, body: Any = None) -> float | None:
    """Seconds the server asks to wait: ``retry-after-ms``, ``Retry-After`` (seconds or an HTTP
    date), ``x-ratelimit-reset-requests`` / ``-tokens`` (the later of the two), or the
    ``retryDelay`` Gemini puts into the error body. None when it says nothing."""
    headers = getattr(response, "headers", None)
    if headers is not None:
        ms = headers.get("retry-after-ms")
        if ms:
            try:
                return max(0.0, float(ms) / 1000.0)
            except ValueError:
                pass
        ra = headers.get("retry-after")
        if ra:
            try:
                return max(0.0, float(ra))
            except ValueError:
                try:
                    when = email.utils.parsedate_to_datetime(ra)
                    return max(0.0, when.timestamp() - time.time())
                except (TypeError, ValueError):
                    pass
        found = [
            _duration(headers.get(h) or "")
            for h in ("x-ratelimit-reset-requests", "x-ratelimit-reset-tokens")
        ]
        resets = [r for r in found if r is not None]
        if resets:
            return max(resets)
    return _retry_delay(body)


def _retry_delay(body: Any) -> float | None:
    """Gemini's ``error.details[].retryDelay`` ("37s"), in a dict or a one-item list body."""
    if isinstance(body, list) and body:
        body = body[0]
    if not isinstance(body, dict):
        return None
    err = body.get("error", body)
    details = err.get("details") if isinstance(err, dict) else None
    for d in details if isinstance(details, list) else []:
        if isinstance(d, dict) and d.get("retryDelay"):
            return _duration(str(d["retryDelay"]))
    return None


def _error_fields(exc: openai.APIStatusError) -> tuple[str, str, str]:
    """(param, code, message) of an error answer, lower-cased; empty strings when absent."""
    body = getattr(exc, "body", None)
    if isinstance(body, list) and body:
        body = body[0]
    err = body.get("error", body) if isinstance(body, dict) else None
    if not isinstance(err, dict):
        return "", "", str(getattr(exc, "message", "") or "").lower()
    param = str(err.get("param") or "").lower()
    code = str(err.get("code") or err.get("status") or err.get("type") or "").lower()
    message = str(err.get("message") or getattr(exc, "message", "") or "").lower()
    return param, code, message


def _short(exc: openai.APIStatusError) -> str:
    body = getattr(exc, "body", None)
    if isinstance(body, list) and body:
        body = body[0]
    if isinstance(body, dict):
        err = body.get("error", body)
        msg = err.get("message") if isinstance(err, dict) else None
        if msg:
            return str(msg)[:200]
    return str(exc.message)[:200]


def _hint_for_status(status: int, provider: str) -> str:
    if status in (401, 403):
        return f"Check the API key for {provider} (environment variable or config file)."
    if status == 404:
        return (
            "Check the model name and the server's base URL (a retired model answers 404: "
            "gemini-2.0-flash is gone, use gemini-2.5-flash; for LM Studio give the loaded "
            "model's id, as `curl URL/models` lists it)."
        )
    return "Check the judge's options and the server's documentation; then resume the run."
