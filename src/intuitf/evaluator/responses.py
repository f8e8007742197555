"""Reading a model server's answers: token usage, the message, retry delays, error hints, and
the corrective follow-up for an answer that could not be used."""

from __future__ import annotations

import email.utils
import time
from typing import Any

import openai

from intuitf.evaluator.parsing import content_text
from intuitf.evaluator.prompts import (
    FOLLOW_UP_REFUSAL,
    FOLLOW_UP_TRUNCATED,
    FOLLOW_UP_UNREADABLE,
)

#: HTTP statuses worth retrying: timeouts, conflicts, rate limits, server trouble.
_RETRYABLE = {408, 409, 425, 429, 500, 502, 503, 504, 520, 522, 524, 529}


def _follow_up(messages: list[dict], reason: str, answer: str | None) -> list[dict]:
    """The conversation to send after an unusable answer (see the module notes)."""
    if reason == "blind":
        return messages  # the images may not have come through: send them again
    text = {
        "refusal": FOLLOW_UP_REFUSAL,
        "truncated": FOLLOW_UP_TRUNCATED,
    }.get(reason, FOLLOW_UP_UNREADABLE)
    return [
        *messages,
        {"role": "assistant", "content": (answer or "")[:4000]},
        {"role": "user", "content": text},
    ]


def _usage(resp: Any) -> tuple[int, int]:
    u = getattr(resp, "usage", None)
    if u is None:
        return 0, 0
    return int(getattr(u, "prompt_tokens", 0) or 0), int(getattr(u, "completion_tokens", 0) or 0)


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


def _retry_after(response: Any) -> float | None:
    """Seconds to wait from ``retry-after-ms`` or ``Retry-After`` (seconds or an HTTP date)."""
    headers = getattr(response, "headers", None)
    if headers is None:
        return None
    ms = headers.get("retry-after-ms")
    if ms:
        try:
            return max(0.0, float(ms) / 1000.0)
        except ValueError:
            pass
    ra = headers.get("retry-after")
    if not ra:
        return None
    try:
        return max(0.0, float(ra))
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(ra)
    except (TypeError, ValueError):
        return None
    return max(0.0, when.timestamp() - time.time())


def _short(exc: openai.APIStatusError) -> str:
    body = getattr(exc, "body", None)
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
        return "Check the model name and the server's base URL."
    return "Check the judge's options and the server's documentation; then resume the run."
