"""How often a judge agrees with people: the paper's agreement score over labelled image pairs.

Each comparison is a Bernoulli choice of the first image: the judge picks it with probability
``p`` (its ``Verdict.p_first``, or the aspect's choice score), people with ``q``. The agreement
score is ``1/N · Σ p·q + (1 - p)(1 - q)``: 1 when both always pick the same image, 0 when they
always differ, 0.5 for a coin against anything.

Labels are JSON Lines, one pair per line (blank lines and lines starting with ``#`` are
skipped)::

    {"first": "renders/a.png", "second": "renders/b.png", "human": "first"}
    {"first": "a.png", "second": "c.png", "human": "tie", "aspect": "feature_discrimination"}
    {"first": "a.png", "second": "d.png", "p_first": 0.75, "text": "red bones, faint skin"}

- ``first``, ``second``: image paths; relative ones are resolved from the JSONL file's folder
  (that is the caller's job: this module reads no files);
- ``human``: ``"first"``, ``"second"`` or ``"tie"`` (q = 1, 0, 0.5), or instead ``p_first``: the
  share of people who preferred the first image (a number in [0, 1]);
- ``aspect`` (optional): the aspect key the label is about; the judge is then asked on that
  aspect alone and its choice there is scored;
- ``text`` (optional): the text intent the pair was judged under.

Scores are reported overall and per aspect (pairs without one count as "overall").
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from intuitf.errors import IntuitfError
from intuitf.evaluator.types import Aspect, Cost, Intent, Judge, Verdict

_HUMAN = {"first": 1.0, "second": 0.0, "tie": 0.5}
OVERALL = "overall"


class LabelError(IntuitfError):
    """A labelled-pairs file is malformed."""


@dataclass(frozen=True)
class LabeledPair:
    """One labelled comparison: image paths as written, people's P(first), optional aspect/text."""

    first: str
    second: str
    q: float
    aspect: str | None = None
    text: str | None = None
    line: int = 0


@dataclass
class AgreementReport:
    """Agreement overall and per aspect, with each pair's judge probability and the cost."""

    score: float
    n: int
    per_aspect: dict[str, tuple[float, int]]
    p_judge: list[float]
    q_human: list[float]
    cost: Cost = field(default_factory=Cost)
    errors: int = 0

    def to_dict(self) -> dict:
        return {
            "score": self.score,
            "n": self.n,
            "per_aspect": {k: {"score": s, "n": n} for k, (s, n) in self.per_aspect.items()},
            "p_judge": list(self.p_judge),
            "q_human": list(self.q_human),
            "cost": self.cost.to_dict(),
            "errors": self.errors,
        }


def agreement_score(p: Sequence[float], q: Sequence[float]) -> float:
    """``1/N · Σ p·q + (1 - p)(1 - q)`` for judge probabilities ``p`` and human ones ``q``."""
    pa, qa = np.asarray(p, dtype=np.float64), np.asarray(q, dtype=np.float64)
    if pa.shape != qa.shape:
        raise ValueError(f"p and q differ in length ({pa.size} vs {qa.size})")
    if pa.size == 0:
        return float("nan")
    return float(np.mean(pa * qa + (1.0 - pa) * (1.0 - qa)))


def parse_pairs(lines: Iterable[str], source: str = "labels") -> list[LabeledPair]:
    """Parse JSONL label lines; a bad line raises :class:`LabelError` naming it."""
    pairs = []
    for number, raw in enumerate(lines, start=1):
        text = raw.strip()
        if not text or text.startswith("#"):
            continue
        where = f"{source}, line {number}"
        try:
            rec = json.loads(text)
        except json.JSONDecodeError as exc:
            raise LabelError(
                f"{where} is not valid JSON ({exc.msg} at column {exc.colno}).",
                'Write one object per line, e.g. {"first": "a.png", "second": "b.png", '
                '"human": "first"}.',
            ) from None
        if not isinstance(rec, dict):
            raise LabelError(f"{where} is not a JSON object.", "Write one object per line.")
        for key in ("first", "second"):
            if not isinstance(rec.get(key), str) or not rec[key].strip():
                raise LabelError(
                    f'{where} has no image path "{key}".',
                    'Give "first" and "second" as image paths (relative to the file is fine).',
                )
        q = _label(rec, where)
        aspect = rec.get("aspect")
        if aspect is not None and (not isinstance(aspect, str) or not aspect.strip()):
            raise LabelError(f'{where}: "aspect" must be an aspect key.', 'E.g. "text_alignment".')
        intent_text = rec.get("text")
        if intent_text is not None and not isinstance(intent_text, str):
            raise LabelError(f'{where}: "text" must be a string.', "Give the intent as text.")
        pairs.append(LabeledPair(rec["first"], rec["second"], q, aspect, intent_text, number))
    if not pairs:
        raise LabelError(f"{source} holds no labelled pairs.", "Add one JSON object per line.")
    return pairs


def _label(rec: dict, where: str) -> float:
    if "human" in rec:
        h = rec["human"]
        if isinstance(h, str) and h.strip().lower() in _HUMAN:
            return _HUMAN[h.strip().lower()]
        raise LabelError(
            f'{where}: "human" is {h!r}.', 'Use "first", "second" or "tie", or give "p_first".'
        )
    if "p_first" in rec:
        v = rec["p_first"]
        if isinstance(v, int | float) and not isinstance(v, bool) and 0.0 <= float(v) <= 1.0:
            return float(v)
        raise LabelError(f'{where}: "p_first" is {v!r}.', "Give a number between 0 and 1.")
    raise LabelError(
        f"{where} has no label.", 'Add "human": "first"|"second"|"tie" or "p_first": 0..1.'
    )


async def evaluate_agreement(
    judge: Judge,
    pairs: Sequence[LabeledPair],
    images: Callable[[str], np.ndarray],
    aspects: Sequence[Aspect],
    *,
    aspect_lookup: Callable[[str], Aspect] | None = None,
    intent: Intent | None = None,
) -> AgreementReport:
    """Ask ``judge`` about every pair (concurrently) and score its agreement with the labels.

    ``images(path)`` returns the uint8 RGB image for a path of the file (the caller loads and
    caches them). ``aspects`` are used for pairs without an aspect; a pair's own aspect is
    looked up with ``aspect_lookup``. ``intent`` applies to pairs without ``text``.
    """
    base_intent = intent or Intent()
    lookup = aspect_lookup or (lambda key: Aspect(key, key, key))

    async def ask(pair: LabeledPair) -> tuple[float, Verdict]:
        asp = [lookup(pair.aspect)] if pair.aspect else list(aspects)
        it = Intent(kind="text", text=pair.text) if pair.text else base_intent
        verdict = await judge.compare(images(pair.first), images(pair.second), asp, it)
        if pair.aspect:
            choice = verdict.per_aspect.get(pair.aspect)
            return (choice.score if choice is not None else 0.5), verdict
        return float(verdict.p_first), verdict

    results = await asyncio.gather(*(ask(pr) for pr in pairs))
    p = [r[0] for r in results]
    q = [pr.q for pr in pairs]
    cost = Cost()
    for _, v in results:
        cost += v.cost
    groups: dict[str, list[int]] = {}
    for i, pr in enumerate(pairs):
        groups.setdefault(pr.aspect or OVERALL, []).append(i)
    per_aspect = {
        k: (agreement_score([p[i] for i in idx], [q[i] for i in idx]), len(idx))
        for k, idx in sorted(groups.items())
    }
    return AgreementReport(
        score=agreement_score(p, q),
        n=len(pairs),
        per_aspect=per_aspect,
        p_judge=p,
        q_human=q,
        cost=cost,
        errors=sum(1 for _, v in results if v.error),
    )
