"""Ratings from pairwise verdicts: Elo's expectation, the Bradley-Terry fit, round counts."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

#: Weight of a verdict from the tournament before, relative to this tournament's own, when
#: the judge is noisy (a model); one from k tournaments ago weighs ``HISTORY_FADE ** k``.
#: Survivors were chosen for their high ratings, lucky wins included; at full weight those
#: wins stay in every later fit (the winner's curse carried along), and an early winner that
#: later candidates beat head to head stayed the best pick. ``benchmarks/tournament.py``
#: measures the pick; a judge whose verdicts are ``deterministic`` has no lucky wins, and its
#: verdicts keep full weight.
HISTORY_FADE = 0.35


def faded(
    games: Sequence[tuple[str, str, float, int]], generation: int, fade: float = HISTORY_FADE
) -> list[tuple[str, str, float, float]]:
    """Verdicts ``(first, second, score, generation played)`` weighted for the fit of
    ``generation``: its own count once, each generation before ``fade`` times less."""
    return [(a, b, s, fade ** max(0, generation - g)) for a, b, s, g in games]


def with_weights(games: Iterable[Sequence[Any]]) -> list[tuple[Any, Any, float, float]]:
    """Games ``(first, second, score[, weight])`` as ``(first, second, score, weight)``: a
    game without a weight counts once."""
    return [(a, b, float(s), float(w[0]) if w else 1.0) for a, b, s, *w in games]


def default_rounds(n: int) -> int:
    """``ceil(log2 n) + 2``, capped so that no pair has to meet twice (0 for n < 2)."""
    if n < 2:
        return 0
    cap = n - 1 if n % 2 == 0 else n  # a round robin's length
    return min(math.ceil(math.log2(n)) + 2, cap)


def elo_expected(r_a: float, r_b: float) -> float:
    """Probability that a player rated ``r_a`` beats one rated ``r_b``."""
    return 1.0 / (1.0 + 10.0 ** ((r_b - r_a) / 400.0))


def bradley_terry(
    n: int,
    games: Sequence[tuple[int, int, float] | tuple[int, int, float, float]],
    anchors: np.ndarray,
    anchor_weight: float | np.ndarray = 1.0,
    iterations: int = 1000,
    tol: float = 1e-10,
) -> np.ndarray:
    """Bradley-Terry ratings (Elo scale) from ``(i, j, score_of_i)`` games among ``n`` players.

    A game may carry a fourth element, its weight: it counts as that many games (earlier
    tournaments' verdicts fade this way, see :data:`HISTORY_FADE`); without one it counts once.
    Each player also plays ``anchor_weight`` (a number, or one per player) virtual drawn games
    against a fixed opponent rated ``anchors[i]``; this keeps undefeated or winless players
    finite and pulls players with few games towards their starting rating. Solved by Hunter's
    minorise-maximise iteration (each step raises the likelihood; converges in tens of steps).
    """
    weights = np.broadcast_to(np.asarray(anchor_weight, dtype=np.float64), (n,))
    anchors = np.asarray(anchors, dtype=np.float64)
    wins = 0.5 * weights.copy()
    # Games counted per unordered pair, so an iteration costs O(pairs), not O(n²): a stage's
    # history can hold hundreds of players, most of whom met only a few others.
    if games:
        g = np.array(with_weights(games), dtype=np.float64)
        i, j, score, weight = g[:, 0].astype(np.int64), g[:, 1].astype(np.int64), g[:, 2], g[:, 3]
        wins += np.bincount(i, weight * score, n) + np.bincount(j, weight * (1.0 - score), n)
        keys, where = np.unique(np.minimum(i, j) * n + np.maximum(i, j), return_inverse=True)
        pi, pj, counts = keys // n, keys % n, np.bincount(where.ravel(), weight)
    else:
        pi = pj = np.zeros(0, dtype=np.int64)
        counts = np.zeros(0)
    centre = float(np.mean(anchors)) if n else 0.0
    # Strengths relative to the mean anchor stay near 1 (no overflow of 10 ** (r / 400)).
    anchor_strength = 10.0 ** ((anchors - centre) / 400.0)
    gamma = anchor_strength.copy()
    for _ in range(iterations):
        per_pair = counts / (gamma[pi] + gamma[pj])
        denom = weights / (gamma + anchor_strength)
        denom = denom + np.bincount(pi, per_pair, n) + np.bincount(pj, per_pair, n)
        new = wins / denom  # wins >= half a virtual point, so new > 0
        converged = np.max(np.abs(np.log(new) - np.log(gamma)), initial=0.0) < tol
        gamma = new
        if converged:
            break
    return 400.0 * np.log10(gamma) + centre
