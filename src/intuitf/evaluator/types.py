"""The vocabulary of judging: aspects, intents, choices, costs, verdicts and the Judge protocol.

A Judge compares two renderings (uint8 RGB arrays, shape (H, W, 3)) under a set of aspects and
the user's intent, and returns a :class:`Verdict`. Judges never see transfer functions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Literal, Protocol, runtime_checkable

import numpy as np


class Choice(StrEnum):
    """Which of two images is better on an aspect (or overall)."""

    FIRST = "first"
    SECOND = "second"
    TIE = "tie"

    @property
    def score(self) -> float:
        """Score of the first image: 1 for a win, 0.5 for a tie, 0 for a loss."""
        return {Choice.FIRST: 1.0, Choice.SECOND: 0.0, Choice.TIE: 0.5}[self]

    def swapped(self) -> Choice:
        """The same choice seen with the two images in the other order."""
        return {Choice.FIRST: Choice.SECOND, Choice.SECOND: Choice.FIRST, Choice.TIE: Choice.TIE}[
            self
        ]


@dataclass(frozen=True)
class Aspect:
    """A named criterion the judge compares on, with its weight in the overall preference."""

    key: str
    name: str
    description: str
    weight: float = 1.0


IntentKind = Literal["none", "text", "image", "sketch", "edit"]


@dataclass(frozen=True, eq=False)
class PartRegion:
    """Where a structure the words name shows in the judge's pictures, and its asked colour.

    ``mask`` (bool, the judging pictures' height x width) is the structure's silhouette from
    the judging camera; ``rgb`` the colour the words give it (in [0, 1]); ``look`` the
    opacity word ("opaque", "semi", "faint") or None. Made by the session from the volume's
    structure map (:mod:`intuitf.intent.regions`), so that a judge that cannot tell a pot
    from leaves by looking can still check each one's colour where it is.
    """

    name: str
    rgb: tuple[float, float, float]
    mask: np.ndarray
    look: str | None = None


@dataclass(eq=False)
class Intent:
    """What the user wants.

    - ``text``: a description ("opaque ivory bone, faint red skin").
    - ``image``: ``reference`` is a picture (uint8 RGB) whose style to match.
    - ``sketch``: ``sketch`` is an RGBA stroke layer (alpha > 0 where drawn) over ``base``,
      the rendering the strokes were drawn on; a stroke means "make this region this colour".
    - ``edit``: ``instruction`` applies to the features ``selected`` (Gaussian indices) of
      ``base``, the rendering before the edit; everything else should be preserved.
      ``selection_mask`` (bool, the base's height x width) marks the pixels those features
      cover in ``base``, so a judge can see where the change should happen, and ``behind``
      is ``base`` with those features hidden: what they cover, where a more transparent
      selection should go (over the background only where nothing lies behind it).
    ``about`` says what the volume is ("a CT of a human foot"), for any kind.
    """

    kind: IntentKind = "none"
    text: str | None = None
    reference: np.ndarray | None = None
    sketch: np.ndarray | None = None
    base: np.ndarray | None = None
    selected: tuple[int, ...] = ()
    about: str | None = None
    selection_mask: np.ndarray | None = None
    part_regions: tuple[PartRegion, ...] = ()
    behind: np.ndarray | None = None

    def fingerprint(self) -> str:
        """A stable hash of the intent's content (for verdict caching).

        ``part_regions`` and ``behind`` are left out: they are worked out from the volume
        (``behind`` from ``base`` and ``selected``, which are in) for the offline
        judge and are not part of what a model is asked.
        """
        import hashlib

        h = hashlib.sha256()
        h.update(f"{self.kind}|{self.text}|{self.about}|{self.selected}".encode())
        for arr in (self.reference, self.sketch, self.base):
            if arr is None:
                h.update(b"-")
            else:
                a = np.ascontiguousarray(arr)
                h.update(f"{a.shape}{a.dtype}".encode())
                h.update(a.tobytes())
        if self.selection_mask is not None:  # absent: the same hash as before the field existed
            m = np.ascontiguousarray(self.selection_mask, dtype=bool)
            h.update(f"selection{m.shape}".encode())
            h.update(np.packbits(m).tobytes())
        return h.hexdigest()

    def validate(self) -> None:
        """Raise :class:`~intuitf.errors.IntuitfError` unless every judge can use this intent.

        Called before a run starts, so that a problem with the user's pictures (a sketch not
        the size of the picture it was drawn on, a sketch with no strokes, a missing picture)
        is reported at once, not by a model judge halfway through a paid run.
        """
        from intuitf.errors import IntuitfError

        def size(a: np.ndarray) -> str:
            return f"{a.shape[1]}x{a.shape[0]}"

        def picture(a, what: str, channels: int) -> None:
            if a is None:
                raise IntuitfError(f"A {self.kind!r} intent needs {what}.")
            if (
                not isinstance(a, np.ndarray)
                or a.ndim != 3
                or a.shape[2] != channels
                or min(a.shape[:2]) < 1
            ):
                shape = getattr(a, "shape", None)
                raise IntuitfError(
                    f"The {what} must be a picture with {channels} channels, got shape {shape}."
                )

        if self.kind not in ("none", "text", "image", "sketch", "edit"):
            raise IntuitfError(
                f"Unknown intent kind {self.kind!r}.", "Use none, text, image, sketch or edit."
            )
        if self.kind == "text" and not (self.text and self.text.strip()):
            raise IntuitfError("A text intent needs some text.", 'Say what you want: --text "..."')
        if self.kind == "image":
            picture(self.reference, "reference picture", 3)
        if self.kind == "sketch":
            picture(self.sketch, "sketch (an RGBA stroke layer)", 4)
            picture(self.base, "picture the sketch was drawn on", 3)
            if self.sketch.shape[:2] != self.base.shape[:2]:
                raise IntuitfError(
                    f"The sketch is {size(self.sketch)} pixels but the picture it was drawn on "
                    f"is {size(self.base)}: the strokes cannot be placed on it.",
                    "Draw the strokes on a transparent layer of exactly the base picture's size "
                    "(and pass that picture with --on).",
                )
            if not np.any(self.sketch[..., 3] > 0):
                raise IntuitfError(
                    "The sketch has no strokes: every pixel of it is transparent.",
                    "Paint coloured strokes on the layer where you want those colours.",
                )
        if self.kind == "edit":
            if not (self.text and self.text.strip()) or not self.selected:
                raise IntuitfError("An edit intent needs an instruction and selected Gaussians.")
            if self.base is not None:
                picture(self.base, "picture before the edit", 3)
        if self.selection_mask is not None and self.base is not None:
            if np.shape(self.selection_mask)[:2] != self.base.shape[:2]:
                raise IntuitfError(
                    f"The selection mask is {np.shape(self.selection_mask)[:2]} but the picture "
                    f"before the edit is {self.base.shape[:2]}."
                )


@dataclass
class Cost:
    """What judging cost: paid model calls, tokens and money, plus answers served from cache."""

    calls: int = 0
    cached_calls: int = 0
    failed_calls: int = 0
    input_tokens: int = 0
    output_tokens: int = 0
    usd: float = 0.0
    seconds: float = 0.0

    def __iadd__(self, other: Cost) -> Cost:
        self.calls += other.calls
        self.cached_calls += other.cached_calls
        self.failed_calls += other.failed_calls
        self.input_tokens += other.input_tokens
        self.output_tokens += other.output_tokens
        self.usd += other.usd
        self.seconds += other.seconds
        return self

    def __add__(self, other: Cost) -> Cost:
        out = Cost(**self.__dict__)
        out += other
        return out

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Verdict:
    """The outcome of one comparison.

    ``per_aspect`` maps aspect keys to choices; ``overall`` is their weighted preference;
    ``p_first`` is the probability the first image is better (1, 0.5 or 0 for a hard verdict).
    ``error`` is set when the judge could not decide for a technical reason (logged tie): the
    verdict is then *undecided* (it carries no information). ``retries`` counts the unusable
    answers (unreadable, truncated, refused, "blind") that were asked again to reach it.
    """

    per_aspect: dict[str, Choice]
    overall: Choice
    p_first: float
    cost: Cost = field(default_factory=Cost)
    rationale: dict[str, str] = field(default_factory=dict)
    cached: bool = False
    error: str | None = None
    retries: int = 0

    @property
    def decided(self) -> bool:
        """Whether the verdict rests on at least one usable answer."""
        return self.error is None

    def swapped(self) -> Verdict:
        """The verdict as if the two images had been given in the other order."""
        return Verdict(
            per_aspect={k: v.swapped() for k, v in self.per_aspect.items()},
            overall=self.overall.swapped(),
            p_first=1.0 - self.p_first,
            cost=self.cost,
            rationale=dict(self.rationale),
            cached=self.cached,
            error=self.error,
            retries=self.retries,
        )

    def to_dict(self) -> dict:
        return {
            "per_aspect": {k: v.value for k, v in self.per_aspect.items()},
            "overall": self.overall.value,
            "p_first": self.p_first,
            "cost": self.cost.to_dict(),
            "rationale": self.rationale,
            "cached": self.cached,
            "error": self.error,
            "retries": self.retries,
        }

    @classmethod
    def from_dict(cls, d: dict) -> Verdict:
        return cls(
            per_aspect={k: Choice(v) for k, v in d["per_aspect"].items()},
            overall=Choice(d["overall"]),
            p_first=float(d["p_first"]),
            cost=Cost(**d.get("cost", {})),
            rationale=dict(d.get("rationale", {})),
            cached=bool(d.get("cached", False)),
            error=d.get("error"),
            retries=int(d.get("retries", 0) or 0),
        )


def combine_answers(
    answers: Sequence[dict[str, Choice]], aspects: Sequence[Aspect]
) -> tuple[Choice, float, dict[str, Choice]]:
    """The one rule that turns answers into a verdict.

    Per aspect, the mean score over ``answers`` (first 1, tie ½, second 0; an answer silent on
    an aspect counts as a tie); overall, P(first better) is the aspects' weighted mean score,
    over the aspects any answer spoke to (an aspect not in ``aspects`` weighs 1). Returns
    (overall choice, P(first better), per-aspect choices); a tie has P exactly ½. Used for one
    answer (the metric judge), both orders of a pair (the model judge) and a re-asked match
    (the tournament).
    """
    weights = {a.key: a.weight for a in aspects}
    spoken = {k for ans in answers for k in ans}
    keys = [a.key for a in aspects if a.key in spoken]
    keys += sorted(spoken - set(keys))
    per: dict[str, Choice] = {}
    num = den = 0.0
    for k in keys:
        score = sum(ans.get(k, Choice.TIE).score for ans in answers) / max(1, len(answers))
        per[k] = _choice(score)
        num += weights.get(k, 1.0) * score
        den += weights.get(k, 1.0)
    p = num / den if den else 0.5
    overall = _choice(p)
    return overall, (p if overall is not Choice.TIE else 0.5), per


def weighted_overall(
    per_aspect: dict[str, Choice], aspects: Sequence[Aspect]
) -> tuple[Choice, float]:
    """One answer's overall choice and P(first better) (see :func:`combine_answers`)."""
    overall, p, _ = combine_answers([per_aspect], aspects)
    return overall, p


def _choice(score: float) -> Choice:
    return (
        Choice.FIRST if score > 0.5 + 1e-9 else Choice.SECOND if score < 0.5 - 1e-9 else Choice.TIE
    )


@runtime_checkable
class Judge(Protocol):
    """Compares two renderings under aspects and an intent.

    A judge may also say ``deterministic = True`` when the same pair always gets the same
    verdict (the offline metric): a run then fits its earlier generations' verdicts at full
    weight instead of fading them (:data:`~intuitf.evaluator.ratings.HISTORY_FADE`).
    """

    #: A short identifier used in cache keys and run records ("metric", "openai:gpt-4o", ...).
    name: str

    async def compare(
        self,
        first: np.ndarray,
        second: np.ndarray,
        aspects: Sequence[Aspect],
        intent: Intent,
    ) -> Verdict:
        """Compare ``first`` and ``second`` (uint8 RGB, shape (H, W, 3))."""
        ...
