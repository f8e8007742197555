"""A person's verdicts in the tournament: preferences, best-of and worst-of, with undo.

A person's verdict is evidence like a model's, only stronger: each one enters the stage's
Bradley-Terry fit with weight :data:`HUMAN_WEIGHT` (a model verdict counts as one game), so a
preference moves a ranking that a handful of model verdicts decided, but does not erase a
clear record. The Session keeps the list (journaled and in its checkpoint); an undone verdict
stays in the list, marked, so the history shows what happened.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

#: How many model verdicts one human verdict is worth in the rating fit.
HUMAN_WEIGHT = 4


@dataclass
class HumanVerdict:
    """``winners`` beat ``losers`` (every winner each loser), said by a person."""

    id: int
    kind: str  # "prefer" | "best" | "worst"
    winners: list[str]
    losers: list[str]
    generation: int
    stage_index: int
    undone: bool = False
    source: str = "human"
    note: str = ""
    games: list[tuple[str, str, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.games:
            self.games = [(w, x, 1.0) for w in self.winners for x in self.losers if w != x]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["games"] = [list(g) for g in self.games]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> HumanVerdict:
        d = dict(d)
        d["games"] = [tuple(g) for g in d.get("games", [])]
        return cls(**d)


def weighted_games(
    verdicts: Sequence[HumanVerdict], stage_index: int
) -> list[tuple[str, str, float, float]]:
    """The active human games of a stage, each with weight :data:`HUMAN_WEIGHT` (the
    Bradley-Terry fit counts a game of weight w as w games)."""
    return [
        (a, b, s, float(HUMAN_WEIGHT))
        for v in verdicts
        if not v.undone and v.stage_index == stage_index
        for a, b, s in v.games
    ]


def stated_orders(verdicts: Sequence[HumanVerdict], stage_index: int) -> list[tuple[str, str]]:
    """The (winner, loser) pairs a person stated in a stage, oldest first."""
    return [
        (w, x)
        for v in verdicts
        if not v.undone and v.stage_index == stage_index
        for w, x, _ in v.games
    ]


def refit_ranking(
    ids: Sequence[str],
    games: Sequence[tuple[str, str, float] | tuple[str, str, float, float]],
    tiebreak: Sequence[str] = (),
    anchor_weight: float = 3.0,
    initial_rating: float = 1600.0,
    stated: Sequence[tuple[str, str]] = (),
) -> tuple[list[str], dict[str, float]]:
    """Ranking and ratings of ``ids`` from all ``games`` (past players join the fit; a game's
    optional fourth element is its weight).

    The same Bradley-Terry fit the efficient tournament uses; ties keep the order of
    ``tiebreak`` (the model's own ranking), so a fit with no new evidence changes nothing.
    ``stated`` pairs (winner, loser) are what a person said outright: the ranking honours
    each one (the newest wins where two disagree), moving the winner just above the loser.
    """
    from intuitf.evaluator.ratings import bradley_terry, with_weights

    index = {pid: i for i, pid in enumerate(ids)}
    pairs: list[tuple[int, int, float, float]] = []
    for a, b, s, weight in with_weights(games):
        for pid in (a, b):
            if pid not in index:
                index[pid] = len(index)
        if a != b:
            pairs.append((index[a], index[b], s, weight))
    n = len(index)
    ratings = bradley_terry(n, pairs, np.full(n, initial_rating), anchor_weight)[: len(ids)]
    order_hint = {pid: i for i, pid in enumerate(tiebreak)}
    ranked = sorted(
        range(len(ids)),
        key=lambda i: (-round(float(ratings[i]), 9), order_hint.get(ids[i], len(order_hint))),
    )
    order = [ids[i] for i in ranked]
    rating = {ids[i]: float(ratings[i]) for i in range(len(ids))}
    # A person's word on a pair stands: newest statements last, so they win a conflict.
    for _ in range(len(stated) + 1):
        moved = False
        for w, x in stated:
            if w in rating and x in rating and order.index(w) > order.index(x):
                order.remove(w)
                order.insert(order.index(x), w)
                rating[w] = max(rating[w], rating[x] + 1.0)
                moved = True
        if not moved:
            break
    return order, rating
