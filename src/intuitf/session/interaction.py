"""What a person does with a running Session: look at results from any camera, pick features,
pause and cancel, give verdicts, ask a new question. A mixin of
:class:`~intuitf.session.session.Session`."""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from intuitf.errors import RunCancelled, SessionError
from intuitf.evaluator.types import Intent
from intuitf.session.helpers import _intent_record, _material_hints, _palette_hint
from intuitf.session.human import HumanVerdict, refit_ranking, stated_orders, weighted_games
from intuitf.session.scheduler import INTERACTIVE, render_scheduler
from intuitf.tf import GaussianTF

if TYPE_CHECKING:
    pass


class SessionInteraction:
    """Views, controls, a person's verdicts and new queries of :class:`Session`."""

    # -- interactive views (own camera, ahead of the tournament's renders) ----------------
    def _tf_of(self, candidate: str | GaussianTF) -> GaussianTF:
        if isinstance(candidate, GaussianTF):
            return candidate
        tf = self.tfs.get(str(candidate))
        if tf is None:
            raise SessionError(
                f"No candidate {candidate!r} in the current population of {self.name or 'this run'}.",
                "Pass a candidate id from the last generation, or a GaussianTF.",
            )
        return tf

    def view(
        self,
        candidate: str | GaussianTF,
        camera=None,
        size: int = 256,
        shaded: bool | None = None,
    ) -> np.ndarray:
        """uint8 RGB of a candidate (or any TF) from ``camera`` (default: the judging one)."""
        tf, cam, shaded = self._tf_of(candidate), camera or self.camera, self._shaded(shaded)
        return render_scheduler().call(lambda: self._views.view(tf, cam, size, shaded), INTERACTIVE)

    async def aview(self, candidate, camera=None, size: int = 256, shaded=None) -> np.ndarray:
        """:meth:`view` for async callers (the render runs on the render worker)."""
        tf, cam, shaded = self._tf_of(candidate), camera or self.camera, self._shaded(shaded)
        return await render_scheduler().run(
            lambda: self._views.view(tf, cam, size, shaded), INTERACTIVE
        )

    def pick(self, candidate, camera=None, x: int = 0, y: int = 0, size: int = 256, shaded=None):
        """The feature under pixel (x, y) of the view: the visible one of smallest area.

        Returns a :class:`~intuitf.session.views.PickResult`.
        """
        tf, cam, shaded = self._tf_of(candidate), camera or self.camera, self._shaded(shaded)
        return render_scheduler().call(
            lambda: self._views.pick(tf, cam, int(x), int(y), size, shaded), INTERACTIVE
        )

    def features(self, candidate, camera=None, size: int = 256, shaded=None) -> list[np.ndarray]:
        """Each Gaussian of the TF rendered alone from ``camera``, in TF order."""
        tf, cam, shaded = self._tf_of(candidate), camera or self.camera, self._shaded(shaded)
        return render_scheduler().call(
            lambda: self._views.features(tf, cam, size, shaded), INTERACTIVE
        )

    def attribution(self, candidate, camera=None, size: int = 256, shaded=None) -> np.ndarray:
        """Each Gaussian's share of every pixel's opacity, float32 (N, size, size)."""
        tf, cam, shaded = self._tf_of(candidate), camera or self.camera, self._shaded(shaded)
        return render_scheduler().call(
            lambda: self._views.attribution(tf, cam, size, shaded), INTERACTIVE
        )

    def _shaded(self, shaded: bool | None) -> bool:
        return self.settings.shading if shaded is None else bool(shaded)

    # -- control --------------------------------------------------------------------------
    def pause(self) -> None:
        """Hold the run before its next match (matches already asked finish)."""
        if not self._paused:
            self._paused = True
            self._refresh("paused" if self._stepping else self._status)
            self.events.emit("status", status="paused")

    def proceed(self) -> None:
        """Let a paused run go on."""
        if self._paused:
            self._paused = False
            self._refresh("running" if self._stepping else self._status)
            self.events.emit("status", status="running")

    def cancel(self) -> None:
        """Stop the run before its next match; the generation is replayed by the next step."""
        self._cancel = True
        self._refresh("cancelling" if self._stepping else self._status)
        self.events.emit("status", status="cancelling")

    async def _gate(self) -> None:
        while self._paused and not self._cancel:
            await asyncio.sleep(0.02)
        if self._cancel:
            raise RunCancelled(
                "The run was cancelled.",
                "Continue it with session.arun() (or --resume); nothing paid for is lost.",
            )

    # -- a person in the loop -------------------------------------------------------------
    def prefer(self, better: str, worse: str, note: str = "") -> HumanVerdict:
        """A person says ``better`` beats ``worse`` (candidate ids of this stage)."""
        return self._add_human("prefer", [str(better)], [str(worse)], note)

    def choose_best(self, best: str, among: Sequence[str], note: str = "") -> HumanVerdict:
        """A person says ``best`` is the best of ``among``."""
        others = [str(c) for c in among if str(c) != str(best)]
        return self._add_human("best", [str(best)], others, note)

    def choose_worst(self, worst: str, among: Sequence[str], note: str = "") -> HumanVerdict:
        """A person says ``worst`` is the worst of ``among``."""
        others = [str(c) for c in among if str(c) != str(worst)]
        return self._add_human("worst", others, [str(worst)], note)

    def undo_verdict(self, verdict_id: int | None = None) -> HumanVerdict:
        """Take back a person's verdict (the last active one by default)."""
        with self._state_lock:
            active = [v for v in self.human if not v.undone]
            if verdict_id is not None:
                active = [v for v in active if v.id == int(verdict_id)]
            if not active:
                raise SessionError("There is no verdict of a person to undo.")
            v = active[-1]
            v.undone = True
            self._apply_human("undone", v)
            return v

    def _add_human(self, kind: str, winners: list[str], losers: list[str], note: str):
        known = set(self.tfs) | {x for g in self._judged_games for x in g[:2]}
        unknown = [c for c in winners + losers if c not in known]
        if unknown or not winners or not losers:
            raise SessionError(
                f"Cannot judge {unknown or 'an empty choice'}: a person's verdict compares "
                "candidates of the current stage.",
                "Use ids shown in the current gallery (e.g. g003-001).",
            )
        with self._state_lock:
            v = HumanVerdict(
                id=len(self.human) + 1,
                kind=kind,
                winners=winners,
                losers=losers,
                generation=self.generation,
                stage_index=self._judged_stage,
                note=note,
            )
            self.human.append(v)
            self._apply_human("added", v)
            return v

    def _apply_human(self, action: str, v: HumanVerdict) -> None:
        """Re-rank the last generation with every active verdict and re-tell the Explorer.

        While a generation is being judged (a paused run, say), the shown ranking of the last
        generation is refitted at once; the Explorer hears the verdict when that generation
        ends (its tournament fit takes the stage's verdicts).
        """
        if self.last_ranking and self._pre_tell is not None:
            if self._stepping:
                self.last_ranking, self.ratings = self._refit()
            else:
                self._retell()
        self._journal({"type": "human", "action": action, "verdict": v.to_dict()})
        if not self._stepping:
            self._checkpoint()
        self._refresh()
        self.events.emit(
            "human_verdict",
            action=action,
            verdict=v.to_dict(),
            ranking=list(self.last_ranking),
            ratings=self.ratings,
        )

    def _human_games(self, stage_index: int | None = None) -> list[tuple[str, str, float]]:
        return weighted_games(self.human, self.stage_index if stage_index is None else stage_index)

    def _retell(self) -> None:
        """Rank the last generation again with a person's verdicts and tell the Explorer anew
        (from its state before the first telling, so undoing every verdict restores it)."""
        from intuitf.explorer import explorer_from_state

        ranking, ratings = self._refit()
        palette = getattr(self.explorer, "palette", None)
        hints = getattr(self.explorer, "hints", None)
        self.explorer = explorer_from_state(self._pre_tell)
        self.explorer.tell(ranking)
        if self.stage_index != self._judged_stage:  # the stage changed after that generation
            stage, n = self.plan[self.stage_index]
            self.explorer.set_stage(stage, generations=n)
            if palette is not None:
                self.explorer.palette = palette
            if hints is not None:
                self.explorer.hints = hints
        self.last_ranking, self.ratings = ranking, ratings

    def _refit(self) -> tuple[list[str], dict[str, float]]:
        """The last generation's ranking and ratings with every active verdict of a person."""
        ids = list(self.last_ranking)
        model_ranking = list(self._model_ranking or ids)
        human = self._human_games(self._judged_stage)
        if not human:
            return model_ranking, dict(self._model_ratings or self.ratings)
        return refit_ranking(
            ids,
            self._judged_games + human,
            tiebreak=model_ranking,
            stated=stated_orders(self.human, self._judged_stage),
        )

    _model_ranking: list[str] | None = None
    _model_ratings: dict[str, float] | None = None

    # -- a new query ----------------------------------------------------------------------
    def query(self, intent: Intent, generations: int | None = None) -> None:
        """Start a new customize stage for ``intent`` after the current generation.

        The run keeps its history; the stage's earlier verdicts answered another question,
        so the new stage starts with none.
        """
        if self._stepping:
            raise SessionError(
                "A new query starts between generations.", "Wait for the generation to end."
            )
        validate = getattr(intent, "validate", None)
        if callable(validate):
            validate()
        n = int(
            generations
            or max(
                1,
                self.settings.generations
                - round(self.settings.generations * self.settings.init_share),
            )
        )
        with self._state_lock:
            self.queries += 1
            folder = f"intent/q{self.queries}"
            pictures = {}
            if self.run_dir is not None:
                from intuitf.session.building import save_intent_pictures

                pictures = save_intent_pictures(intent, self.run_dir.root, folder)
            self.intent = intent
            # The stage now in progress ends here (or is dropped if it has not begun); the
            # new one follows.
            done_in_stage = self.generation - sum(k for _, k in self.plan[: self.stage_index])
            kept = self.plan[: self.stage_index]
            if done_in_stage > 0:
                kept.append((self.plan[self.stage_index][0], done_in_stage))
            self.plan = [*kept, ("customize", n)]
            self.stage_index = len(self.plan) - 1
            self.stage_games = []
            palette = _palette_hint(intent, self.settings)
            if hasattr(self.explorer, "palette") and palette:
                from intuitf.explorer.base import _palette

                self.explorer.palette = _palette(palette)
            if hasattr(self.explorer, "hints"):  # the new words name their own materials
                from intuitf.explorer.hints import as_hints

                self.explorer.hints = as_hints(_material_hints(intent, self.settings, self.volume))
            self.explorer.set_stage("customize", generations=n)
            record = {"type": "query", "generation": self.generation, "intent": _intent_record(intent), "pictures": pictures}  # fmt: skip
            self._journal(record)
            self._journal({"type": "stage", "generation": self.generation, "stage": "customize"})
            self._current_intent_record = {**_intent_record(intent), "pictures": pictures}
            self._checkpoint()
            self._refresh()
        self.events.emit("query", generation=self.generation, intent=_intent_record(intent))
        self.events.emit(
            "stage_started", stage="customize", generations=n, generation=self.generation
        )

    _current_intent_record: dict | None = None
