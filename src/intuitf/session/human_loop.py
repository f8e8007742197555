"""The human-verdict loop of a Session: a person's verdicts, their undo, and the re-ranking of
the last generation (and re-telling of the Explorer) each one causes.

:class:`HumanVerdicts` holds everything a person's verdicts need between generations (the
verdicts, the Explorer's state before its last telling, the model's own ranking and the games
the last generation was ranked with) and reaches the session only through :class:`VerdictHost`:
the few fields it reads and re-ranks, and one callback that journals and announces a change.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

from intuitf.errors import SessionError
from intuitf.evaluator.ratings import with_weights
from intuitf.session.human import HumanVerdict, refit_ranking, stated_orders, weighted_games
from intuitf.tf import GaussianTF

__all__ = ["HumanVerdicts", "VerdictHost"]

#: A verdict with its weight in the fit (a model's: its generation's fade; a person's:
#: :data:`~intuitf.session.human.HUMAN_WEIGHT`).
WeightedGame = tuple[str, str, float, float]


class VerdictHost(Protocol):
    """What the verdict loop needs from its session."""

    #: The Explorer; a verdict between generations replaces it with a re-told one.
    explorer: Any
    #: The last generation's ranking and ratings, which a verdict re-ranks.
    last_ranking: list[str]
    ratings: dict[str, float]
    #: The stage plan and the stage now in progress.
    plan: list[tuple[str, int]]
    stage_index: int
    generation: int

    #: The current population by candidate id (a verdict may name any of them).
    tfs: dict[str, GaussianTF]

    @property
    def stepping(self) -> bool:
        """Whether a generation is being judged right now."""
        ...


class HumanVerdicts:
    """A person's verdicts of one run and their effect on the last generation's ranking.

    ``on_change(action, verdict)`` is called after each verdict is added or undone (and the
    ranking re-fitted): the session journals, checkpoints and announces it there.
    """

    def __init__(
        self,
        host: VerdictHost,
        on_change: Callable[[str, HumanVerdict], None],
        verdicts: Sequence[HumanVerdict] = (),
        *,
        pre_tell: dict[str, Any] | None = None,
        judged_games: Sequence[Sequence[Any]] = (),
        judged_stage: int = 0,
    ) -> None:
        self._host = host
        self._on_change = on_change
        #: Every verdict a person gave in this run (undone ones stay, marked).
        self.verdicts: list[HumanVerdict] = list(verdicts)
        #: The Explorer's state before the last ``tell``: a person's verdict re-tells it.
        self.pre_tell: dict[str, Any] | None = pre_tell
        #: The last generation's ranking and ratings as the model's tournament gave them.
        self.model_ranking: list[str] | None = None
        self.model_ratings: dict[str, float] | None = None
        #: The model verdicts the last generation was ranked with, weighted as then, and its
        #: stage (a stage change resets the stage's games; a person may still judge the last
        #: generation's gallery).
        self.judged_games: list[WeightedGame] = _weighted(judged_games)
        self.judged_stage = int(judged_stage)

    # -- checkpoint -----------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """The loop's part of a checkpoint."""
        return {
            "human": [h.to_dict() for h in self.verdicts],
            "pre_tell": self.pre_tell,
            "model_ranking": self.model_ranking,
            "model_ratings": self.model_ratings,
            "judged_games": [list(g) for g in self.judged_games],
            "judged_stage": self.judged_stage,
        }

    def restore(self, ckpt: dict[str, Any]) -> None:
        """Take the loop's state from a checkpoint written by :meth:`state` (older checkpoints
        without the judged games keep the ones given at construction)."""
        self.verdicts = [HumanVerdict.from_dict(h) for h in ckpt.get("human", [])]
        self.pre_tell = ckpt.get("pre_tell")
        self.model_ranking = ckpt.get("model_ranking")
        self.model_ratings = ckpt.get("model_ratings")
        if "judged_games" in ckpt:
            self.judged_games = _weighted(ckpt["judged_games"])
            self.judged_stage = int(ckpt.get("judged_stage", self._host.stage_index))

    # -- verdicts -------------------------------------------------------------------------
    def add(self, kind: str, winners: list[str], losers: list[str], note: str) -> HumanVerdict:
        """Enter a person's verdict: ``winners`` beat ``losers`` (ids of the current stage)."""
        host = self._host
        known = set(host.tfs) | {x for g in self.judged_games for x in g[:2]}
        unknown = [c for c in winners + losers if c not in known]
        if unknown or not winners or not losers:
            raise SessionError(
                f"Cannot judge {unknown or 'an empty choice'}: a person's verdict compares "
                "candidates of the current stage.",
                "Use ids shown in the current gallery (e.g. g003-001).",
            )
        v = HumanVerdict(
            id=len(self.verdicts) + 1,
            kind=kind,
            winners=winners,
            losers=losers,
            generation=host.generation,
            stage_index=self.judged_stage,
            note=note,
        )
        self.verdicts.append(v)
        self._apply("added", v)
        return v

    def undo(self, verdict_id: int | None = None) -> HumanVerdict:
        """Take back a verdict (the last active one by default)."""
        active = [v for v in self.verdicts if not v.undone]
        if verdict_id is not None:
            active = [v for v in active if v.id == int(verdict_id)]
        if not active:
            raise SessionError("There is no verdict of a person to undo.")
        v = active[-1]
        v.undone = True
        self._apply("undone", v)
        return v

    def games(self, stage_index: int) -> list[WeightedGame]:
        """The active verdicts of a stage as weighted games for the tournament's fit."""
        return weighted_games(self.verdicts, stage_index)

    # -- ranking --------------------------------------------------------------------------
    def rank_generation(
        self,
        explorer_state: dict[str, Any],
        ids: list[str],
        model_ranking: list[str],
        model_ratings: dict[str, float],
        stage_games: Sequence[Sequence[Any]],
        stage_index: int,
    ) -> tuple[list[str], dict[str, float]]:
        """The ranking of a generation just judged: the model's, refit with a person's verdicts
        of this stage when there are any. Remembers what a later verdict re-ranks from."""
        self.pre_tell = explorer_state
        self.model_ranking = list(model_ranking)
        self.model_ratings = dict(model_ratings)
        self.judged_games, self.judged_stage = _weighted(stage_games), stage_index
        human = self.games(stage_index)
        if not human:  # the model's ranking stands exactly as the tournament gave it
            return list(model_ranking), dict(model_ratings)
        return refit_ranking(
            ids,
            [*self.judged_games, *human],
            tiebreak=list(model_ranking),
            stated=stated_orders(self.verdicts, stage_index),
        )

    def refit(self) -> tuple[list[str], dict[str, float]]:
        """The last generation's ranking and ratings with every active verdict of a person."""
        host = self._host
        ids = list(host.last_ranking)
        model_ranking = list(self.model_ranking or ids)
        human = self.games(self.judged_stage)
        if not human:
            return model_ranking, dict(self.model_ratings or host.ratings)
        return refit_ranking(
            ids,
            [*self.judged_games, *human],
            tiebreak=model_ranking,
            stated=stated_orders(self.verdicts, self.judged_stage),
        )

    def retell(self) -> None:
        """Rank the last generation again with a person's verdicts and tell the Explorer anew
        (from its state before the first telling, so undoing every verdict restores it)."""
        from intuitf.explorer import explorer_from_state

        host = self._host
        ranking, ratings = self.refit()
        palette = getattr(host.explorer, "palette", None)
        hints = getattr(host.explorer, "hints", None)
        assert self.pre_tell is not None  # _apply re-tells only after a first telling
        explorer = explorer_from_state(self.pre_tell)
        explorer.tell(ranking)
        if host.stage_index != self.judged_stage:  # the stage changed after that generation
            stage, n = host.plan[host.stage_index]
            explorer.set_stage(stage, generations=n)
            if palette is not None:
                explorer.palette = palette
            if hints is not None:
                explorer.hints = hints
        host.explorer = explorer
        host.last_ranking, host.ratings = ranking, ratings

    def _apply(self, action: str, v: HumanVerdict) -> None:
        """Re-rank the last generation with every active verdict and re-tell the Explorer.

        While a generation is being judged (a paused run, say), the shown ranking of the last
        generation is refitted at once; the Explorer hears the verdict when that generation
        ends (its tournament fit takes the stage's verdicts).
        """
        host = self._host
        if host.last_ranking and self.pre_tell is not None:
            if host.stepping:
                host.last_ranking, host.ratings = self.refit()
            else:
                self.retell()
        self._on_change(action, v)


def _weighted(games: Sequence[Sequence[Any]]) -> list[WeightedGame]:
    """Games as (first id, second id, score, weight) (:func:`with_weights`)."""
    return [(str(a), str(b), s, w) for a, b, s, w in with_weights(games)]
