"""An in-process judge that answers like the fake model server, without HTTP or images sent.

:class:`OracleJudge` follows :func:`~intuitf.testing.fake_mllm.oracle_choice` (the fake
server's answer rule: position bias, then the higher score, then noise) with its own seeded
random numbers. It skips everything between a judge and a model (prompts, PNG encoding,
HTTP, parsing), so a search experiment with many seeds runs several times faster; use the
fake server with the real :class:`~intuitf.evaluator.mllm.MLLMJudge` for measurements of the
product itself.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence

import numpy as np

from intuitf.evaluator.types import Aspect, Choice, Cost, Intent, Verdict
from intuitf.testing.fake_mllm import oracle_choice

_CHOICES = {"first": Choice.FIRST, "second": Choice.SECOND, "cannot decide": Choice.TIE}


class OracleJudge:
    """Prefers the image with the higher ``score(image)``, with noise and position bias.

    Scores are memoised per image content. ``cost.calls`` counts comparisons like paid calls.
    """

    name = "oracle"

    def __init__(
        self,
        score: Callable[[np.ndarray], float],
        *,
        noise: float = 0.0,
        position_bias: float = 0.0,
        seed: int = 0,
    ) -> None:
        self.score_fn = score
        self.noise = float(noise)
        self.position_bias = float(position_bias)
        self.rng = np.random.default_rng(seed)
        self.cost = Cost()
        self._scores: dict[str, float] = {}

    def score(self, image: np.ndarray) -> float:
        key = hashlib.sha1(np.ascontiguousarray(image).tobytes()).hexdigest()
        if key not in self._scores:
            self._scores[key] = float(self.score_fn(image))
        return self._scores[key]

    async def compare(
        self, first: np.ndarray, second: np.ndarray, aspects: Sequence[Aspect], intent: Intent
    ) -> Verdict:
        u_bias, u_noise = self.rng.random(), self.rng.random()
        choice = _CHOICES[
            oracle_choice(
                lambda: (self.score(first), self.score(second)),
                u_bias,
                u_noise,
                position_bias=self.position_bias,
                noise=self.noise,
            )
        ]
        cost = Cost(calls=1)
        self.cost += cost
        return Verdict({a.key: choice for a in aspects}, choice, choice.score, cost=cost)
