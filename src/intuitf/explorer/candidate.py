"""A candidate transfer function with the identity and lineage the session records."""

from __future__ import annotations

from dataclasses import dataclass

from intuitf.tf.gaussian import GaussianTF


@dataclass(frozen=True)
class Candidate:
    """One member of a population.

    ``id`` is stable and unique within a run (``"g003-017"``: made in generation 3, 17th
    of that generation); an elite carried into later generations keeps its id, so its
    rendering and verdicts can be reused. ``origin`` says how it was made ("initial",
    "seed", "random", "elite", "crossover", "mutation", "cma", ...) and ``parents`` names
    the ids it came from.
    """

    id: str
    tf: GaussianTF
    generation: int
    origin: str
    parents: tuple[str, ...] = ()

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "tf": self.tf.to_dict(),
            "generation": self.generation,
            "origin": self.origin,
            "parents": list(self.parents),
        }

    @classmethod
    def from_dict(cls, d: dict) -> Candidate:
        return cls(
            id=str(d["id"]),
            tf=GaussianTF.from_dict(d["tf"]),
            generation=int(d["generation"]),
            origin=str(d["origin"]),
            parents=tuple(str(p) for p in d.get("parents", ())),
        )


def candidate_id(generation: int, index: int) -> str:
    """The id of the ``index``-th candidate made in ``generation``."""
    return f"g{generation:03d}-{index:03d}"
