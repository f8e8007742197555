"""Reading a model's answer, whether it is clean JSON, JSON in a code fence, or free text.

:func:`parse_answer` returns a choice per aspect, or raises :class:`UnreadableAnswer` with a
reason ("refusal", "blind" when the model says it cannot see the images, "unreadable"), which the
judge turns into a logged tie. Aspects the answer leaves out are ties.

Reasoning models write around their answer: ``<think>``/``<thought>`` blocks (possibly holding
braces and draft JSON) are dropped first, then every JSON value in the text is decoded and the
*last* one that names the expected aspects is the answer (a draft followed by the final one reads
as the final one). Content given as a list of parts (text and reasoning parts) is read from its
text parts only.
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
    r"(provided|attached|shown)|images? (did not|didn't) (load|come through)|"
    r"images? (was |were |is |are )?not (found|attached|provided)",
    re.IGNORECASE,
)
#: Reasoning a model writes before its answer, in the tags the common chat templates use.
_THINK = re.compile(
    r"<(think|thinking|thought|reasoning|reflection)>.*?</\1\s*>", re.IGNORECASE | re.DOTALL
)
_THINK_OPEN = re.compile(r"<(think|thinking|thought|reasoning)>", re.IGNORECASE)
_THINK_CLOSE = re.compile(r"</(think|thinking|thought|reasoning)\s*>", re.IGNORECASE)
#: Part types that carry reasoning, not the answer, in list-of-parts content.
_REASONING_PARTS = {"reasoning", "thinking", "thought", "reasoning_content", "redacted_thinking"}
_REFUSAL = re.compile(
    r"\b(i'm sorry|i am sorry|i can(no|')t (help|assist|comply)|i (won't|will not)|"
    r"unable to (help|assist|comply)|as an ai)\b",
    re.IGNORECASE,
)

#: Mentions of one candidate in prose ("Image 2", "the first image", "image B", "left one").
_MENTION = re.compile(
    r"\b(?:image|picture|candidate|option)\s*(?P<num>[12ab])\b"
    r"|\b(?P<word>first|second|left|right)\b(?:\s+(?:image|one|picture|candidate))?",
    re.IGNORECASE,
)
_BETTER = re.compile(
    r"\b(better|superior|preferred|prefer(?:able)?|clearer|stronger|wins?|outperforms?|beats?|"
    r"more (?:faithful|accurate|informative|vivid|appealing))\b",
    re.IGNORECASE,
)
_WORSE = re.compile(r"\b(worse|inferior|weaker|loses?|less (?:faithful|accurate|clear))\b", re.I)


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
    if any(w in s for w in ("cannot decide", "can't decide", "equally", "neither")) or re.search(
        r"\btie\b", s
    ):
        return Choice.TIE
    return _choice_in_prose(s)


def _mentioned(m: re.Match) -> Choice:
    token = (m.group("num") or m.group("word") or "").lower()
    return Choice.FIRST if token in ("1", "a", "first", "left") else Choice.SECOND


def _choice_in_prose(s: str) -> Choice | None:
    """The candidate a sentence prefers: the only one it names, or the winner of a comparison
    ("Image 2 is better than Image 1", "I prefer the second image over the first", "Image 1 is
    worse than Image 2"). None when it names both and the comparison is not understood."""
    mentions = list(_MENTION.finditer(s))
    named = {_mentioned(m) for m in mentions}
    if not named:
        return None
    if len(named) == 1:
        return named.pop()
    first = mentions[0]
    other = next(m for m in mentions if _mentioned(m) is not _mentioned(first))
    between = s[first.end() : other.start()]
    before = s[: first.start()]
    if _WORSE.search(between):
        return _mentioned(other)
    if _BETTER.search(between) or _BETTER.search(before):
        return _mentioned(first)
    return None


def strip_reasoning(text: str) -> str:
    """``text`` without the reasoning a model wrote around its answer (``<think>`` blocks; an
    unclosed one runs to the end; a closing tag without its opening drops what precedes it)."""
    out = _THINK.sub(" ", text)
    close = list(_THINK_CLOSE.finditer(out))
    if close:  # the template put the opening tag into the prompt
        out = out[close[-1].end() :]
    opened = _THINK_OPEN.search(out)
    if opened:  # cut off while still thinking
        out = out[: opened.start()]
    return out.strip()


def content_text(content: object) -> str | None:
    """The answer text of a message's ``content``: a string, or a list of parts whose text
    parts are joined (reasoning parts are left out)."""
    if content is None or isinstance(content, str):
        return content
    if isinstance(content, list):
        texts = []
        for part in content:
            if isinstance(part, str):
                texts.append(part)
                continue
            kind = _field(part, "type")
            if kind in _REASONING_PARTS or _field(part, "thought") is True:
                continue
            text = _field(part, "text")
            if isinstance(text, str):
                texts.append(text)
        return "\n".join(texts)
    return str(content)


def _field(part: object, name: str) -> object:
    return part.get(name) if isinstance(part, dict) else getattr(part, name, None)


def _json_values(text: str) -> list[object]:
    """Every JSON object or array in ``text``, in order (nested ones inside their parent)."""
    decoder = json.JSONDecoder()
    out: list[object] = []
    i = 0
    while True:
        starts = [j for j in (text.find("{", i), text.find("[", i)) if j >= 0]
        if not starts:
            return out
        j = min(starts)
        try:
            value, end = decoder.raw_decode(text, j)
        except ValueError:
            i = j + 1
            continue
        out.append(value)
        i = end


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


def parse_answer(text: object, aspects: Sequence[Aspect]) -> ParsedAnswer:
    """The choices in a model's answer; raise :class:`UnreadableAnswer` when there are none.

    ``text`` is the message content: a string or a list of parts.
    """
    text = content_text(text)
    if text is None or not text.strip():
        raise UnreadableAnswer("unreadable", "empty answer")
    stripped = strip_reasoning(text)
    if not stripped:
        raise UnreadableAnswer("unreadable", "only reasoning, no answer")
    if CANNOT_SEE.lower() in stripped.lower():
        raise UnreadableAnswer("blind", stripped[:200])
    parsed: ParsedAnswer | None = None
    # The last JSON value that names the aspects: a draft followed by the final answer is read
    # as the final answer.
    for data in reversed(_json_values(stripped)):
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
