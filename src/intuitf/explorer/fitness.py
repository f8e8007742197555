"""From a ranking to selection fitness, with selection pressure that rises over the run."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PressureSchedule:
    """``pressure = min + (max - min) * progress ** k``, as in the paper (1.2, 4.0, k = 2)."""

    min_pressure: float = 1.2
    max_pressure: float = 4.0
    k: float = 2.0

    def pressure(self, progress: float) -> float:
        p = min(1.0, max(0.0, float(progress)))
        return self.min_pressure + (self.max_pressure - self.min_pressure) * p**self.k


def rank_fitness(n: int, progress: float, schedule: PressureSchedule | None = None) -> np.ndarray:
    """Fitness of ranks 1..n (best first): ``(n - rank + 1) ** pressure(progress)``."""
    sched = schedule or PressureSchedule()
    ranks = np.arange(1, n + 1, dtype=np.float64)
    return (n - ranks + 1.0) ** sched.pressure(progress)
