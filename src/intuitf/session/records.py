"""What a session reports: generation records, the run's outcome, and read-only snapshots."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from intuitf.evaluator.types import Cost
from intuitf.tf import GaussianTF


@dataclass
class GenerationRecord:
    """One generation's outcome, as written to the journal."""

    generation: int
    stage: str
    ranking: list[str]
    ratings: dict[str, float]
    candidates: list[dict]
    cost: Cost
    seconds: float
    #: Matches decided, undecided (a tie for a technical reason) and asked more than once.
    match_stats: dict[str, int] = field(default_factory=dict)

    @property
    def best_id(self) -> str:
        return self.ranking[0]


@dataclass
class RunOutcome:
    """How a run ended and where its results are."""

    #: "completed" | "budget" | "judge" | "interrupted" | "cancelled" | "storage"
    reason: str
    message: str
    generations_done: int
    cost: Cost
    run_dir: Path | None
    best: list[tuple[GaussianTF, float]]

    @property
    def completed(self) -> bool:
        return self.reason == "completed"


@dataclass(frozen=True)
class SessionSnapshot:
    """An immutable picture of a session, safe to read from any thread while it runs.

    The session replaces its snapshot (one reference assignment) whenever its state changes;
    readers never see a half-updated session.
    """

    name: str
    status: str  # "idle" | "running" | "paused" | "cancelling" | "ended"
    stage: str
    generation: int
    generations: int
    plan: tuple[tuple[str, int], ...]
    ranking: tuple[str, ...]
    ratings: MappingProxyType
    tfs: MappingProxyType
    cost: Cost
    last_seq: int
    ended: str | None = None  # the end reason once the run has ended

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "status": self.status,
            "stage": self.stage,
            "generation": self.generation,
            "generations": self.generations,
            "plan": [list(p) for p in self.plan],
            "ranking": list(self.ranking),
            "ratings": dict(self.ratings),
            "cost": self.cost.to_dict(),
            "last_seq": self.last_seq,
            "ended": self.ended,
        }
