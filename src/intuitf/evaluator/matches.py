"""What a tournament produces: judged matches, their counts, and the result of a tournament."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from intuitf.evaluator.types import Cost, Verdict


@dataclass
class MatchRecord:
    """One judged match: in round ``round`` (1-based), ``first`` was shown first."""

    round: int
    first: str
    second: str
    verdict: Verdict
    #: True when the verdict averages a second ask in the other order (``recheck_above``).
    rechecked: bool = False

    def to_dict(self) -> dict:
        return {
            "round": self.round,
            "first": self.first,
            "second": self.second,
            "verdict": self.verdict.to_dict(),
            "rechecked": self.rechecked,
        }

    @classmethod
    def from_dict(cls, d: dict) -> MatchRecord:
        return cls(
            int(d["round"]),
            str(d["first"]),
            str(d["second"]),
            Verdict.from_dict(d["verdict"]),
            bool(d.get("rechecked", False)),
        )


#: Above this share of undecided matches, a run's summary and report warn.
UNDECIDED_WARNING = 0.05


@dataclass
class MatchStats:
    """How many matches were decided (a usable answer), undecided (none), or needed a re-ask."""

    matches: int = 0
    decided: int = 0
    undecided: int = 0
    retried: int = 0

    @classmethod
    def of(cls, matches: Sequence[MatchRecord]) -> MatchStats:
        out = cls()
        for m in matches:
            out.matches += 1
            if m.verdict.decided:
                out.decided += 1
            else:
                out.undecided += 1
            if m.verdict.retries > 0:
                out.retried += 1
        return out

    @classmethod
    def from_journal(cls, entries: Sequence[dict]) -> MatchStats:
        """The totals over journal "generation" entries (counted from their matches if needed)."""
        out = cls()
        for e in entries:
            if "undecided" in e and "decided" in e:
                out += cls(
                    int(e.get("decided", 0)) + int(e.get("undecided", 0)),
                    int(e.get("decided", 0)),
                    int(e.get("undecided", 0)),
                    int(e.get("retried", 0)),
                )
            else:
                ms = []
                for m in e.get("matches", []) or []:
                    try:
                        ms.append(MatchRecord.from_dict(m))
                    except (KeyError, TypeError, ValueError):
                        continue
                out += cls.of(ms)
        return out

    def __iadd__(self, other: MatchStats) -> MatchStats:
        self.matches += other.matches
        self.decided += other.decided
        self.undecided += other.undecided
        self.retried += other.retried
        return self

    @property
    def undecided_share(self) -> float:
        return self.undecided / self.matches if self.matches else 0.0

    @property
    def warning(self) -> str | None:
        """A sentence for the user when too many matches stayed undecided, else None."""
        if self.undecided_share <= UNDECIDED_WARNING:
            return None
        return (
            f"{self.undecided} of {self.matches} matches ({100 * self.undecided_share:.0f} %) "
            "stayed undecided: the model gave no usable answer even when asked again, so the "
            "ranking rests on less evidence than it seems. Check the model and its server (the "
            "journal's verdict errors say what it answered)."
        )

    def to_dict(self) -> dict:
        return {"decided": self.decided, "undecided": self.undecided, "retried": self.retried}

    def summary(self) -> str:
        return (
            f"{self.matches} match(es): {self.decided} decided, {self.undecided} undecided, "
            f"{self.retried} asked again"
        )


@dataclass
class TournamentResult:
    """Ratings, ranking (best first) and every judged match of one tournament.

    ``elo`` holds the plain Elo ratings; ``ratings`` the ratings the ranking is based on (equal
    to ``elo`` under the paper protocol, the Bradley-Terry fit under the efficient one).
    ``complete`` is False for the partial result attached to an exception.
    """

    ratings: dict[str, float]
    ranking: list[str]
    matches: list[MatchRecord]
    cost: Cost
    rounds: int
    wall_seconds: float
    elo: dict[str, float] = field(default_factory=dict)
    byes: list[tuple[int, str]] = field(default_factory=list)
    protocol: str = "efficient"
    complete: bool = True

    def match_stats(self) -> MatchStats:
        """Decided, undecided and re-asked matches of this tournament."""
        return MatchStats.of(self.matches)

    def to_dict(self) -> dict:
        """A JSON-able form (verdicts via ``Verdict.to_dict``)."""
        return {
            "ratings": dict(self.ratings),
            "elo": dict(self.elo),
            "ranking": list(self.ranking),
            "matches": [m.to_dict() for m in self.matches],
            "byes": [[r, pid] for r, pid in self.byes],
            "cost": self.cost.to_dict(),
            "rounds": self.rounds,
            "wall_seconds": self.wall_seconds,
            "protocol": self.protocol,
            "complete": self.complete,
        }

    @classmethod
    def from_dict(cls, d: dict) -> TournamentResult:
        return cls(
            ratings={k: float(v) for k, v in d["ratings"].items()},
            ranking=list(d["ranking"]),
            matches=[MatchRecord.from_dict(m) for m in d["matches"]],
            cost=Cost(**d.get("cost", {})),
            rounds=int(d["rounds"]),
            wall_seconds=float(d.get("wall_seconds", 0.0)),
            elo={k: float(v) for k, v in d.get("elo", {}).items()},
            byes=[(int(r), str(p)) for r, p in d.get("byes", [])],
            protocol=str(d.get("protocol", "efficient")),
            complete=bool(d.get("complete", True)),
        )
