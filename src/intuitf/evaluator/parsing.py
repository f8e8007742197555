"""Reading a model's answer, whether it is clean JSON, JSON in a code fence, or free text.

:func:`parse_answer` returns a choice per aspect, or raises :class:`UnreadableAnswer` with a
reason ("refusal", "blind" when the model says it cannot see the images, "unreadable"), which the
judge turns into a logged tie. Aspects the answer leaves out are ties.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from dataclasses import dataclass, field

from intuitf.evaluator.prompts import CANNOT_SEE
from intuitf.evaluator.types import Aspect, Choice


class UnreadableAnswer(ValueError):
    """An answer with no usable choice; ``reason`` is "refusal", "blind" or "unreadable"."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


@dataclass
class ParsedAnswer:
    """Choices by aspect key (in the order the images were shown), analyses and notes."""

    per_aspect: dict[str, Choice]
    rationale: dict[str, str] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)
    reference_description: str | None = None


_FIRST = {"first", "1", "a", "image 1", "image a", "left", "the first", "first image", "1st"}
_SECOND = {"second", "2", "b", "image 2", "image b", "right", "the second", "second image", "2nd"}
_TIE = {
    "cannot decide",
    "can't decide",
    "tie",
    "3",
    "equal",
    "draw",
    "neither",
    "undecided",
    "same",
    "none",
    "both",
    "c",
    "cannot_decide",
    "unsure",
}

_BLIND = re.compile(
    r"cannot see|can't see|can not see|unable to (see|view|access)|no images? (was|were|is|are) "
    r"(provided|attached|shown)|images? (did not|didn't) (load|come through)|not found",
    re.IGNORECASE,
)
_REFUSAL = re.compile(
    r"\b(i'm sorry|i am sorry|i can(no|')t (help|assist|comply)|i (won't|will not)|"
    r"unable to (help|assist|comply)|as an ai)\b",
    re.IGNORECASE,
)
_FENCE = re.compile(r"```(?:json|JSON)?\s*(.*?)```", re.DOTALL)


def normalise_choice(value: object) -> Choice | None:
    """A choice from the ways models say it: "first", "1", "A", "Image 2", "cannot decide"..."""
    if isinstance(value, bool) or value is None:
        return None
    if isinstance(value, int | float):
        value = str(int(value)) if float(value).is_integer() else str(value)
    s = re.sub(r"[\s\"'`*.!:;,()\[\]]+", " ", str(value).strip().lower()).strip()
    for prefix in ("the ", "option ", "choice "):
        if s.startswith(prefix) and s not in _FIRST | _SECOND | _TIE:
            s = s[len(prefix) :]
    if s in _FIRST:
        return Choice.FIRST
    if s in _SECOND:
        return Choice.SECOND
    if s in _TIE:
        return Choice.TIE
    for words, choice in (
        (("cannot decide", "can't decide", "tie", "equally", "neither"), Choice.TIE),
        (("image 1", "first image", "the first", "image a", "left one"), Choice.FIRST),
        (("image 2", "second image", "the second", "image b", "right one"), Choice.SECOND),
    ):
        if any(w in s for w in words):
            return choice
    return None


def _json_candidates(text: str) -> list[str]:
    """Substrings that may hold the answer's JSON, most likely first."""
    out = [m.group(1) for m in _FENCE.finditer(text)]
    out.append(text)
    # The outermost {...} span, for JSON wrapped in prose.
    start, end = text.find("{"), text.rfind("}")
    if 0 <= start < end:
        out.append(text[start : end + 1])
    return out


def _choice_of(entry: object) -> tuple[Choice | None, str]:
    if isinstance(entry, dict):
        lowered = {str(k).lower(): v for k, v in entry.items()}
        for k in ("choice", "answer", "better", "winner", "preference", "result"):
            if k in lowered:
                analysis = (
                    lowered.get("analysis") or lowered.get("reason") or lowered.get("rationale")
                )
                return normalise_choice(lowered[k]), str(analysis or "")
        return None, ""
    return normalise_choice(entry), ""


def _from_json(data: object, aspects: Sequence[Aspect]) -> ParsedAnswer | None:
    keys = [a.key for a in aspects]
    by_name = {a.name.lower(): a.key for a in aspects} | {k.lower(): k for k in keys}
    ref = None
    if isinstance(data, dict):
        ref = data.get("reference_description")
        body = data.get("aspects", data)
        if isinstance(body, list):
            body = {
                str(e.get("aspect") or e.get("key") or e.get("name") or ""): e
                for e in body
                if isinstance(e, dict)
            }
    elif isinstance(data, list):
        body = {str(e.get("aspect") or e.get("key") or ""): e for e in data if isinstance(e, dict)}
    else:
        return None
    if not isinstance(body, dict):
        return None
    per: dict[str, Choice] = {}
    why: dict[str, str] = {}
    for raw_key, entry in body.items():
        key = by_name.get(str(raw_key).strip().strip("[]").lower())
        if key is None:
            continue
        choice, analysis = _choice_of(entry)
        if choice is not None:
            per[key] = choice
            if analysis:
                why[key] = analysis
    # A single-aspect answer may come as a bare {"choice": ...}.
    if not per and len(keys) == 1:
        choice, analysis = _choice_of(body)
        if choice is not None:
            per[keys[0]] = choice
            if analysis:
                why[keys[0]] = analysis
    if not per:
        return None
    return ParsedAnswer(per, why, reference_description=ref if isinstance(ref, str) else None)


def _from_lines(text: str, aspects: Sequence[Aspect]) -> ParsedAnswer | None:
    """Free text: "key: first" / "1. Name: Image 2" lines, or a "Final answer: 1 2 3" line."""
    keys = [a.key for a in aspects]
    per: dict[str, Choice] = {}
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    # "Final answer:" lines win over analyses that mention both images.
    for i, ln in enumerate(lines):
        m = re.match(r"^\W*final answers?\W*[:\-]\s*(.*)$", ln, re.IGNORECASE)
        if not m:
            continue
        rest = m.group(1).strip()
        # Per-aspect "key: choice" pairs on the marker's line and the lines after it?
        found: dict[str, Choice] = {}
        for tail in [rest, *lines[i + 1 :]]:
            found.update({k: c for k, c in _keyed(tail, aspects).items() if k not in found})
        if found:
            return ParsedAnswer(found)
        if not rest and i + 1 < len(lines):
            rest = lines[i + 1]
        toks = [t for t in re.split(r"[\s,;/|]+", rest) if t]
        choices = [normalise_choice(t) for t in toks]
        if rest and normalise_choice(rest) is not None and len(keys) == 1:
            return ParsedAnswer({keys[0]: normalise_choice(rest)})  # type: ignore[dict-item]
        if choices and all(c is not None for c in choices) and len(choices) >= len(keys):
            return ParsedAnswer(dict(zip(keys, choices, strict=False)))  # type: ignore[arg-type]
    for ln in lines:
        per.update(_keyed(ln, aspects))
    if per:
        return ParsedAnswer(per)
    return None


def _keyed(line: str, aspects: Sequence[Aspect]) -> dict[str, Choice]:
    out: dict[str, Choice] = {}
    low = line.lower()
    for a in aspects:
        for label in (f"[{a.key.lower()}]", a.key.lower(), a.name.lower()):
            idx = low.find(label)
            if idx < 0:
                continue
            tail = low[idx + len(label) :]
            m = re.match(r"\W*[:=\-]+\s*([^,;|]+)", tail)
            if m:
                c = normalise_choice(m.group(1))
                if c is not None:
                    out[a.key] = c
                    break
    return out


def parse_answer(text: str | None, aspects: Sequence[Aspect]) -> ParsedAnswer:
    """The choices in a model's answer; raise :class:`UnreadableAnswer` when there are none."""
    if text is None or not text.strip():
        raise UnreadableAnswer("unreadable", "empty answer")
    stripped = text.strip()
    if CANNOT_SEE.lower() in stripped.lower():
        raise UnreadableAnswer("blind", stripped[:200])
    parsed: ParsedAnswer | None = None
    for cand in _json_candidates(stripped):
        try:
            data = json.loads(cand)
        except (json.JSONDecodeError, ValueError):
            continue
        parsed = _from_json(data, aspects)
        if parsed is not None:
            break
    if parsed is None:
        parsed = _from_lines(stripped, aspects)
    if parsed is None:
        if _BLIND.search(stripped):
            raise UnreadableAnswer("blind", stripped[:200])
        if _REFUSAL.search(stripped):
            raise UnreadableAnswer("refusal", stripped[:200])
        raise UnreadableAnswer("unreadable", stripped[:200])
    for a in aspects:
        if a.key not in parsed.per_aspect:
            parsed.per_aspect[a.key] = Choice.TIE
            parsed.missing.append(a.key)
    parsed.per_aspect = {a.key: parsed.per_aspect[a.key] for a in aspects}
    return parsed
