"""The Explorer concept: what every search method offers the Session, in ask/tell style.

The genetic algorithm (:class:`~intuitf.explorer.ga.GeneticExplorer`), CMA-ES
(:class:`~intuitf.explorer.cmaes.CMAExplorer`) and random search
(:class:`~intuitf.explorer.random_search.RandomSearchExplorer`) all implement it, like
Optuna's samplers behind one study: the Session only asks, tells and saves.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

from intuitf.explorer.candidate import Candidate


@runtime_checkable
class Explorer(Protocol):
    """A search over transfer functions driven by rankings (it never sees an image)."""

    def ask(self) -> list[Candidate]:
        """The candidates to render and rank; the same list until :meth:`tell`."""
        ...

    def tell(self, ranking: Sequence[str], fitness: Sequence[float] | None = None) -> None:
        """Their ids best first (and, optionally, a fitness each); builds the next population."""
        ...

    @property
    def done(self) -> bool:
        """Whether the current stage has run all its generations."""
        ...

    @property
    def best(self) -> Candidate | None:
        """The top candidate of the last :meth:`tell`."""
        ...

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue bit for bit (see ``explorer_from_state``)."""
        ...
