"""The Session: Trial (render) → Insight (judge) → Replanning (evolve), generation after generation.

A Session owns the loop, the stage plan (initialize → customize → refine), the run directory
and its journal. The command line, the web app, batch runs and the Python API all drive this
class the same way; none of them holds algorithm or run-building logic of its own:

- :meth:`Session.open` starts a run from a :class:`~intuitf.session.spec.RunSpec` (plain
  data), :meth:`Session.resume` continues a run folder, :meth:`Session.branch` starts a run
  from any generation or candidate of another; :meth:`Session.create` takes in-memory
  objects (a volume, an intent, a judge) for notebooks and tests.
- ``await session.astep()`` / ``await session.arun()`` work inside a running event loop
  (FastAPI, Jupyter); ``step()`` / ``run()`` are the same for scripts.
- :meth:`pause`, :meth:`proceed` and :meth:`cancel` act between matches; a cancelled
  generation is replayed by the next step (or a resume) with no paid call repeated.
- :attr:`events` numbers, journals and fans out typed events; :meth:`snapshot` is an
  immutable view for other threads.
- :meth:`prefer`, :meth:`choose_best` and :meth:`choose_worst` enter a person's verdicts;
  :meth:`undo_verdict` takes one back; :meth:`query` starts a new customize stage.
- :meth:`view`, :meth:`pick`, :meth:`features` and :meth:`attribution` render with their own
  camera, ahead of the tournament's renders, and never touch the judging camera.

Resuming: a checkpoint is written after every generation (and kept per generation, so a
branch can start from any of them). A run that stopped for any reason (crash, kill, Ctrl-C,
budget, lost server, full disk, cancel) is continued with :meth:`Session.resume`. The
generation that was in flight is replayed: the Explorer state, the renderings and the
tournament's seed are the same, so the tournament asks the same questions and the verdict
store answers every one that was already paid for.
"""

from __future__ import annotations

import asyncio
import functools
import hashlib
import threading
import time
from collections.abc import Callable, Coroutine, Sequence
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from intuitf.errors import (
    BudgetExhausted,
    IntuitfError,
    JudgeError,
    RunCancelled,
    SessionError,
    StorageError,
)
from intuitf.evaluator.ratings import HISTORY_FADE, faded
from intuitf.evaluator.types import Aspect, Cost, Intent, Judge
from intuitf.session import opening
from intuitf.session.events import EventLog
from intuitf.session.helpers import (
    _fit_line,
    _fit_sketch,
    _intent_record,
    _judge_name,
    _paid,
    _palette_hint,
    _read_intent,
)
from intuitf.session.human import HumanVerdict
from intuitf.session.human_loop import HumanVerdicts
from intuitf.session.recorder import RunRecorder, recorder_for
from intuitf.session.records import GenerationRecord, RunOutcome, SessionSnapshot
from intuitf.session.rundir import RunDirectory
from intuitf.session.scheduler import BATCH, INTERACTIVE, render_scheduler
from intuitf.session.settings import RunSettings
from intuitf.session.spec import RunSpec
from intuitf.tf import GaussianTF
from intuitf.volume import Volume

if TYPE_CHECKING:
    from intuitf.render import Camera
    from intuitf.render.cache import CacheViews
    from intuitf.session.lock import RunLock
    from intuitf.session.views import PickResult, ViewRenderer

__all__ = ["Session"]

S = TypeVar("S", bound="Session")
T = TypeVar("T")

#: Mean absolute difference (0-255 scale) under which two renderings count as the same picture.
_SAME_PICTURE = 1.0


def _generation_seed(seed: int, generation: int) -> int:
    """A per-generation seed for the tournament: independent of anything but the run seed."""
    h = hashlib.sha256(f"{seed}:{generation}".encode()).digest()
    return int.from_bytes(h[:4], "little")


def _aspects_for_stage(stage_aspects: str, intent: Intent) -> list[Aspect]:
    from intuitf.intent.aspects import aspects_for, aspects_for_intent

    if stage_aspects == "quality" or intent.kind == "none":
        return aspects_for("quality")
    if stage_aspects == "edit":
        return aspects_for("edit")
    return aspects_for_intent(intent)


class _GatedJudge:
    """The session's judge behind its pause and cancel controls: checked before every match."""

    def __init__(self, session: Session, judge: Judge) -> None:
        self._session = session
        self._judge = judge
        self.name = getattr(judge, "name", type(judge).__name__)

    async def compare(
        self, first: np.ndarray, second: np.ndarray, aspects: Sequence[Aspect], intent: Intent
    ) -> Any:
        await self._session._gate()
        return await self._judge.compare(first, second, aspects, intent)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._judge, name)


class Session:
    """An optimisation run over one volume, one judging camera and an intent.

    Build one with :meth:`open` (a spec), :meth:`resume` (a run folder), :meth:`branch`, or
    :meth:`create` (in-memory objects; ``run_dir=None`` keeps everything in memory).

    Made of parts: the run's :attr:`recorder` (journal, checkpoints, pictures), its
    :attr:`events`, its :attr:`views` (interactive renders), the human-verdict loop
    (:class:`~intuitf.session.human_loop.HumanVerdicts`, behind :meth:`prefer` and its kin)
    and the opening functions of :mod:`intuitf.session.opening` (behind the classmethods).
    """

    # -- construction (intuitf.session.opening) -------------------------------------------
    @classmethod
    def open(
        cls: type[S],
        spec: RunSpec | dict[str, Any],
        run_dir: str | Path | None,
        *,
        overwrite: bool = False,
        judge: Judge | None = None,
        volume: Volume | None = None,
    ) -> S:
        """Start the run ``spec`` describes in ``run_dir`` (None: in memory).

        Builds the volume, the judge (with its verdict store in the run folder and its
        budget), the intent (its pictures copied into the run folder) and the Explorer. A
        ``judge`` or ``volume`` given here is used instead of building one (tests, notebooks).
        """
        return opening.open_session(
            cls, spec, run_dir, overwrite=overwrite, judge=judge, volume=volume
        )

    @classmethod
    def create(
        cls: type[S],
        volume: Volume,
        *,
        intent: Intent | None = None,
        judge: Judge | None = None,
        settings: RunSettings | None = None,
        run_dir: str | Path | None = None,
        initial: Sequence[GaussianTF] = (),
        overwrite: bool = False,
        spec: RunSpec | None = None,
    ) -> S:
        """Start a new run from in-memory objects. ``initial`` TFs join the first population."""
        return opening.create_session(
            cls, volume, intent=intent, judge=judge, settings=settings, run_dir=run_dir,
            initial=initial, overwrite=overwrite, spec=spec,
        )  # fmt: skip

    @classmethod
    def refine(
        cls: type[S],
        volume: Volume,
        tf: GaussianTF,
        selected: Sequence[int],
        instruction: str,
        *,
        judge: Judge | None = None,
        settings: RunSettings | None = None,
        run_dir: str | Path | None = None,
        about: str | None = None,
        overwrite: bool = False,
    ) -> S:
        """A run of the refine stage: only the Gaussians ``selected`` (indices into ``tf``) change.

        The judge sees the rendering before the edit and ``instruction``, and prefers
        candidates where the change happened in the selected features and the rest is kept.
        """
        return opening.refine_session(
            cls, volume, tf, selected, instruction, judge=judge, settings=settings,
            run_dir=run_dir, about=about, overwrite=overwrite,
        )  # fmt: skip

    @classmethod
    def resume(
        cls: type[S],
        run_dir: str | Path,
        volume: Volume | None = None,
        judge: Judge | None = None,
        *,
        evaluator: str | None = None,
        base_url: str | None = None,
        budget_usd: float | None = None,
        budget_calls: int | None = None,
        judge_options: dict[str, Any] | None = None,
    ) -> S:
        """Continue the run in ``run_dir`` from its last checkpoint.

        The volume and the judge are rebuilt from the run's spec unless given. ``evaluator``
        and ``base_url`` move the run to another model or server (recorded in ``run.json``);
        the budgets replace the run's and count everything the run already paid.
        """
        return opening.resume_session(
            cls, run_dir, volume, judge, evaluator=evaluator, base_url=base_url,
            budget_usd=budget_usd, budget_calls=budget_calls, judge_options=judge_options,
        )  # fmt: skip

    @classmethod
    def branch(
        cls: type[S],
        parent_dir: str | Path,
        run_dir: str | Path,
        *,
        generation: int | None = None,
        candidate: str | None = None,
        changes: dict[str, Any] | None = None,
        judge: Judge | None = None,
        volume: Volume | None = None,
    ) -> S:
        """A new run that starts where ``parent_dir``'s run was at ``generation``, or from its
        ``candidate`` (an id like ``g003-007``), with ``changes`` to its spec (plain data,
        merged field by field: a new intent, judge, settings, ...).

        From a generation with an unchanged spec, the branch reproduces the parent's run from
        there: the Explorer's state, the stage, the ratings and the verdicts are the parent's
        at that point. From a candidate, the candidate joins a fresh first population (as
        ``--start-from`` does) and the branch starts its own plan.
        """
        return opening.branch_session(
            cls, parent_dir, run_dir, generation=generation, candidate=candidate,
            changes=changes, judge=judge, volume=volume,
        )  # fmt: skip

    def __init__(
        self,
        volume: Volume,
        *,
        intent: Intent,
        judge: Judge,
        settings: RunSettings,
        run_dir: RunDirectory | None,
        explorer: Any,
        stage_index: int = 0,
        generation: int = 0,
        cost: Cost | None = None,
        ratings: dict[str, float] | None = None,
        last_ranking: list[str] | None = None,
        population_tfs: dict[str, GaussianTF] | None = None,
        stage_games: Sequence[Sequence[Any]] = (),
        plan: Sequence[Sequence[Any]] | None = None,
        spec: RunSpec | None = None,
        human: Sequence[HumanVerdict] = (),
        pre_tell: dict[str, Any] | None = None,
        queries: int = 0,
        lock: RunLock | None = None,
    ) -> None:
        from intuitf.render import Camera, VolumeRenderer
        from intuitf.render.context import render_context
        from intuitf.session.views import ViewRenderer

        self.volume = volume
        self.intent = intent
        #: How the intent was read on the volume, for a person to check (set at opening).
        self.understood: list[str] = []
        self.judge = judge
        self.settings = settings
        self.run_dir = run_dir
        self.explorer = explorer
        self.spec = spec
        self.name = run_dir.root.name if run_dir is not None else (spec.name if spec else "") or ""
        self.plan: list[tuple[str, int]] = (
            [(str(s), int(n)) for s, n in plan]
            if plan
            else settings.stage_plan(intent.kind != "none")
        )
        self.stage_index = stage_index
        self.generation = generation
        self.cost = cost or Cost()
        #: What the run had paid when its last generation was checkpointed: a generation's
        #: journal entry counts everything paid since, a killed attempt of it included.
        self._paid_at_checkpoint = Cost()
        self.ratings: dict[str, float] = dict(ratings or {})
        self.last_ranking: list[str] = list(last_ranking or [])
        self.tfs: dict[str, GaussianTF] = dict(population_tfs or {})
        #: The current stage's model verdicts so far, (first id, second id, score of first,
        #: generation): the tournament fits them with each new generation's (a model judge's
        #: faded by age), so survivors keep their evidence. (A checkpoint without the
        #: generation: the last.)
        self.stage_games: list[tuple[str, str, float, int]] = [
            (str(a), str(b), float(s), int(rest[0]) if rest else generation - 1)
            for a, b, s, *rest in stage_games
        ]
        #: A person's verdicts, their undo and the re-ranking they cause (the human loop).
        self._verdicts = HumanVerdicts(
            self,
            self._verdict_changed,
            human,
            pre_tell=pre_tell,
            judged_games=self._faded_games(generation - 1),
            judged_stage=stage_index,
        )
        #: New questions asked during the run (:meth:`query`), and the current one's record.
        self.queries = int(queries)
        self._current_intent_record: dict[str, Any] | None = None
        self.camera = Camera.from_dict(settings.camera) if settings.camera else Camera()
        # The run's device becomes its volume's (unless something named one first), so the
        # views, picks and previews of this run render where its generations do.
        render_context(volume, settings.device)
        self.renderer = VolumeRenderer(
            volume,
            size=settings.image_size,
            shading=settings.shading,
            background=tuple(settings.background),
            device=settings.device,
        )
        self._views = ViewRenderer(
            volume, background=tuple(settings.background), device=settings.device
        )
        self._cache: Any = None
        self._images: dict[str, np.ndarray] = {}
        #: (intent, camera, the intent the judge is given), for :meth:`_judged_intent`.
        self._judged: tuple[Any, dict, Intent] | None = None
        self.records: list[GenerationRecord] = []
        self.generation_seconds: list[float] = []
        #: Where the journal, checkpoints and pictures go (a run folder, or memory).
        self.recorder: RunRecorder = recorder_for(run_dir)
        self.events = EventLog(self.name, self.recorder.events_path)
        self._lock = lock
        self._state_lock = threading.RLock()
        self._status = "idle"
        self._ended: str | None = None
        self._paused = False
        self._cancel = False
        self._stepping = False
        self._snapshot: SessionSnapshot | None = None
        #: Whether the resume that made this session moved the run to another judge.
        self.judge_moved = False
        # A private event loop for the synchronous wrappers (step/run): model clients keep
        # connections bound to the loop they were made in.
        self._loop: asyncio.AbstractEventLoop | None = None
        #: Wrappers around the judge each generation's tournament asks (add_judge_middleware).
        self._judge_middleware: list[Callable[[Any], Any]] = []
        #: Called with the seconds of each render job of a generation (on_render).
        self._render_hooks: list[Callable[[float], None]] = []
        self._refresh()

    # -- hooks ----------------------------------------------------------------------------
    def add_judge_middleware(self, wrap: Callable[[Any], Any]) -> None:
        """Put ``wrap(judge)`` around the judge that each generation's tournament asks.

        For code that drives sessions (a rate limiter shared by a worker's runs, a recorder):
        ``wrap`` takes a judge and returns one with the same ``compare``. Wrappers apply in the
        order added, the first innermost; the session's pause and cancel gate stays outermost,
        so a paused run holds no limiter slot. :attr:`judge` itself is left as it is (costs
        and the verdict store are read from it).
        """
        self._judge_middleware.append(wrap)

    def on_render(self, fn: Callable[[float], None]) -> Callable[[], None]:
        """Call ``fn(seconds)`` after each render job of a generation (the sample cache for
        the judging camera, the candidates' pictures), with the time the job took on the
        render thread; returns a function that removes the hook."""
        self._render_hooks.append(fn)

        def remove() -> None:
            if fn in self._render_hooks:
                self._render_hooks.remove(fn)

        return remove

    def _tournament_judge(self) -> Any:
        judge = self.judge
        for wrap in self._judge_middleware:
            judge = wrap(judge)
        return _GatedJudge(self, judge)

    def _timed(self, job: Callable[[], Any]) -> Callable[[], Any]:
        """``job`` reporting its duration to the render hooks (none: ``job`` itself)."""
        if not self._render_hooks:
            return job

        def timed() -> Any:
            t = time.perf_counter()
            try:
                return job()
            finally:
                took = time.perf_counter() - t
                for fn in list(self._render_hooks):
                    fn(took)

        return timed

    # -- state ----------------------------------------------------------------------------
    @property
    def stage(self) -> str:
        return self.plan[min(self.stage_index, len(self.plan) - 1)][0]

    @property
    def total_generations(self) -> int:
        return sum(n for _, n in self.plan)

    @property
    def done(self) -> bool:
        return self.generation >= self.total_generations

    @property
    def status(self) -> str:
        return self._status

    @property
    def stepping(self) -> bool:
        """Whether a generation is being judged right now."""
        return self._stepping

    @property
    def human(self) -> list[HumanVerdict]:
        """Every verdict a person gave in this run (undone ones stay, marked)."""
        return self._verdicts.verdicts

    @property
    def views(self) -> ViewRenderer:
        """The :class:`~intuitf.session.views.ViewRenderer` of this run's interactive views
        (own camera and size, on the run's device and background)."""
        return self._views

    @property
    def judge_name(self) -> str:
        """The judge's name, with any credentials in a URL redacted."""
        return _judge_name(self.judge)

    @property
    def lock(self) -> RunLock | None:
        """The run folder's lock (None in memory)."""
        return self._lock

    def snapshot(self) -> SessionSnapshot:
        """An immutable view of the session, safe to read from any thread."""
        snap = self._snapshot
        assert snap is not None
        return snap

    def _refresh(self, status: str | None = None) -> None:
        if status is not None:
            self._status = status
        self._snapshot = SessionSnapshot(
            name=self.name,
            status=self._status,
            stage=self.stage,
            generation=self.generation,
            generations=self.total_generations,
            plan=tuple((str(s), int(n)) for s, n in self.plan),
            ranking=tuple(self.last_ranking),
            ratings=MappingProxyType(dict(self.ratings)),
            tfs=MappingProxyType(dict(self.tfs)),
            cost=Cost(**self.cost.to_dict()),
            last_seq=self.events.last_seq,
            ended=self._ended,
        )

    def _stage_end(self) -> int:
        return sum(n for _, n in self.plan[: self.stage_index + 1])

    def sample_cache(self) -> CacheViews:
        """The sample cache for the judging camera (built on first use)."""
        if self._cache is None:
            self._cache = self.renderer.sample_cache(self.camera)
        return self._cache

    def set_camera(self, camera: Camera) -> None:
        """Change the judging camera; the tournament's renderings are redone for it.

        To look at a result from another side, use :meth:`view`, which leaves the judging
        camera alone.
        """
        if self._stepping:
            raise SessionError(
                "The judging camera cannot change while a generation is being judged.",
                "Use session.view(...) to look from another camera, or change it between steps.",
            )
        self.camera = camera
        self.settings.camera = camera.to_dict()
        self._cache = None
        self._images.clear()

    def _judged_intent(self) -> Intent:
        """The intent as the judge gets it: with the picture regions of the structures its
        words name (:func:`intuitf.intent.regions.part_regions`), worked out once per intent
        and judging camera."""
        cam = self.camera.to_dict()
        if self._judged is None or self._judged[0] is not self.intent or self._judged[1] != cam:
            from dataclasses import replace

            from intuitf.intent.regions import part_regions

            regions = part_regions(self.intent, self.volume, self.camera, self.renderer.size)
            self._judged = (self.intent, cam, replace(self.intent, part_regions=regions))
        return self._judged[2]

    def image(self, candidate_id: str, tf: GaussianTF) -> np.ndarray:
        """The judging rendering of a candidate, rendered once and remembered."""
        img = self._images.get(candidate_id)
        if img is None:
            img = self.sample_cache().render(tf)
            self._images[candidate_id] = img
        return img

    def render(
        self,
        tf: GaussianTF,
        *,
        size: int | None = None,
        camera: Camera | None = None,
        shading: bool | None = None,
    ) -> np.ndarray:
        """Render any TF with the session's volume (and judging camera unless given)."""
        size = size or self.settings.output_size
        shading = self.settings.shading if shading is None else shading
        if size == self.settings.image_size and camera is None and shading == self.settings.shading:
            return self.sample_cache().render(tf)
        return self._views.view(tf, camera or self.camera, size, shading)

    def best(self, k: int = 1, distinct: bool = True) -> list[tuple[GaussianTF, float]]:
        """The top ``k`` TFs of the last judged generation, with their ratings.

        With ``distinct`` (the default), a TF whose rendering looks the same as that of one
        ranked above it (mean difference under 1/255, as when only a hidden feature differs)
        is passed over for the next one: k results are k different pictures.
        """
        return [(tf, r) for _, tf, r in self.best_candidates(k, distinct)]

    def best_candidates(
        self, k: int = 1, distinct: bool = True
    ) -> list[tuple[str, GaussianTF, float]]:
        """Like :meth:`best`, with each result's candidate id."""
        out: list[tuple[str, GaussianTF, float]] = []
        shown: list[np.ndarray] = []
        for cid in self.last_ranking:
            if len(out) >= k:
                break
            tf = self.tfs.get(cid)
            if tf is None:
                continue
            if distinct:
                img = self.image(cid, tf).astype(np.float32)
                if any(np.abs(img - other).mean() < _SAME_PICTURE for other in shown):
                    continue
                shown.append(img)
            out.append((cid, tf, self.ratings.get(cid, float("nan"))))
        return out

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

    def _interactive(
        self,
        candidate: str | GaussianTF,
        camera: Camera | None,
        shaded: bool | None,
        job: Callable[[GaussianTF, Camera, bool], T],
    ) -> Callable[[], T]:
        """``job`` for the render worker, with the TF, camera and shading resolved now."""
        tf, cam, shade = self._tf_of(candidate), camera or self.camera, self._shaded(shaded)
        return lambda: job(tf, cam, shade)

    def view(
        self,
        candidate: str | GaussianTF,
        camera: Camera | None = None,
        size: int = 256,
        shaded: bool | None = None,
    ) -> np.ndarray:
        """uint8 RGB of a candidate (or any TF) from ``camera`` (default: the judging one)."""
        views = self._views
        job = self._interactive(candidate, camera, shaded,
                                lambda tf, cam, sh: views.view(tf, cam, size, sh))  # fmt: skip
        return render_scheduler().call(job, INTERACTIVE)

    async def aview(
        self,
        candidate: str | GaussianTF,
        camera: Camera | None = None,
        size: int = 256,
        shaded: bool | None = None,
    ) -> np.ndarray:
        """:meth:`view` for async callers (the render runs on the render worker)."""
        views = self._views
        job = self._interactive(candidate, camera, shaded,
                                lambda tf, cam, sh: views.view(tf, cam, size, sh))  # fmt: skip
        return await render_scheduler().run(job, INTERACTIVE)

    def pick(
        self,
        candidate: str | GaussianTF,
        camera: Camera | None = None,
        x: int = 0,
        y: int = 0,
        size: int = 256,
        shaded: bool | None = None,
        whole: bool = False,
    ) -> PickResult:
        """The feature under pixel (x, y) of the view: of those that make the pixel (see
        :func:`~intuitf.session.views.pick_smallest`), the one of smallest projected area;
        with ``whole``, all of them (:func:`~intuitf.session.views.pick_whole`).

        Returns a :class:`~intuitf.session.views.PickResult`; its ``selected`` is what to
        refine.
        """
        views = self._views
        job = self._interactive(
            candidate, camera, shaded,
            lambda tf, cam, sh: views.pick(tf, cam, int(x), int(y), size, sh, whole=whole),
        )  # fmt: skip
        return render_scheduler().call(job, INTERACTIVE)

    def features(
        self,
        candidate: str | GaussianTF,
        camera: Camera | None = None,
        size: int = 256,
        shaded: bool | None = None,
    ) -> list[np.ndarray]:
        """Each Gaussian of the TF rendered alone from ``camera``, in TF order."""
        views = self._views
        job = self._interactive(candidate, camera, shaded,
                                lambda tf, cam, sh: views.features(tf, cam, size, sh))  # fmt: skip
        return render_scheduler().call(job, INTERACTIVE)

    def attribution(
        self,
        candidate: str | GaussianTF,
        camera: Camera | None = None,
        size: int = 256,
        shaded: bool | None = None,
    ) -> np.ndarray:
        """Each Gaussian's share of every pixel's opacity, float32 (N, size, size)."""
        views = self._views
        job = self._interactive(candidate, camera, shaded,
                                lambda tf, cam, sh: views.attribution(tf, cam, size, sh))  # fmt: skip
        return render_scheduler().call(job, INTERACTIVE)

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

    # -- a person in the loop (intuitf.session.human_loop) --------------------------------
    def prefer(self, better: str, worse: str, note: str = "") -> HumanVerdict:
        """A person says ``better`` beats ``worse`` (candidate ids of this stage)."""
        with self._state_lock:
            return self._verdicts.add("prefer", [str(better)], [str(worse)], note)

    def choose_best(self, best: str, among: Sequence[str], note: str = "") -> HumanVerdict:
        """A person says ``best`` is the best of ``among``."""
        others = [str(c) for c in among if str(c) != str(best)]
        with self._state_lock:
            return self._verdicts.add("best", [str(best)], others, note)

    def choose_worst(self, worst: str, among: Sequence[str], note: str = "") -> HumanVerdict:
        """A person says ``worst`` is the worst of ``among``."""
        others = [str(c) for c in among if str(c) != str(worst)]
        with self._state_lock:
            return self._verdicts.add("worst", others, [str(worst)], note)

    def undo_verdict(self, verdict_id: int | None = None) -> HumanVerdict:
        """Take back a person's verdict (the last active one by default)."""
        with self._state_lock:
            return self._verdicts.undo(verdict_id)

    def _verdict_changed(self, action: str, v: HumanVerdict) -> None:
        """A verdict was added or undone (and the ranking re-fitted): journal it, checkpoint
        between generations, and announce the new ranking."""
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
            pictures: dict[str, str] = {}
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
            # The new words name their own materials, and the person is told how they were
            # read, as at the opening.
            hints, self.understood, reading = _read_intent(intent, self.settings, self.volume)
            if hasattr(self.explorer, "hints"):
                from intuitf.explorer.hints import as_hints

                self.explorer.hints = as_hints(hints)
            # A sketch asked now is fitted as at an opening: its TF joins the population.
            fitted = _fit_sketch(intent, self.settings, self.volume, reading)
            if fitted is not None:
                self.understood = [*self.understood, _fit_line(fitted, intent, opening=False)]
            joining = [fitted.tf] if fitted is not None else []
            self.explorer.set_stage("customize", generations=n, joining=joining)
            record = {"type": "query", "generation": self.generation, "intent": _intent_record(intent), "pictures": pictures, "understood": self.understood}  # fmt: skip
            self._journal(record)
            self._journal({"type": "stage", "generation": self.generation, "stage": "customize"})
            self._current_intent_record = {**_intent_record(intent), "pictures": pictures}
            self._checkpoint()
            self._refresh()
        self.events.emit("query", generation=self.generation, intent=_intent_record(intent))
        self.events.emit(
            "stage_started", stage="customize", generations=n, generation=self.generation
        )

    # -- the loop -------------------------------------------------------------------------
    async def astep(self) -> GenerationRecord:
        """Run one generation: ask, render, judge, tell, record (journal, checkpoint, events)."""
        if self.done:
            raise SessionError("This run has already done all its generations.")
        if self._stepping:
            raise SessionError("This session is already running a generation.")
        self._stepping = True
        self._cancel = False
        self._refresh("paused" if self._paused else "running")
        try:
            t0 = time.perf_counter()
            g = self.generation
            candidates = self._ask(g)
            images = await self._render(g, candidates)
            base_cost = Cost(**self.cost.to_dict())
            result = await self._judge(g, candidates, images, base_cost)
            ranking, ratings = self._tell(candidates, result)
            return self._record(g, t0, candidates, result, base_cost, ranking, ratings)
        finally:
            self._stepping = False
            self._refresh("idle")

    # -- the parts of a generation ---------------------------------------------------------
    def _ask(self, g: int) -> list[Any]:
        """The Explorer's candidates for generation ``g`` (announced, their TFs kept)."""
        candidates = list(self.explorer.ask())
        self.events.emit(
            "generation_started", generation=g, stage=self.stage, population=len(candidates)
        )
        for c in candidates:
            self.tfs[c.id] = c.tf
        return candidates

    async def _render(self, g: int, candidates: list[Any]) -> list[np.ndarray]:
        """Each candidate's judging picture, rendered on the render thread (one job each, so
        interactive renders can go between them; on the GPU a generation is one launch)."""
        ids = [c.id for c in candidates]
        sched = render_scheduler()
        cache = await sched.run(self._timed(self.sample_cache), BATCH)
        todo = [c for c in candidates if c.id not in self._images]
        if getattr(self.renderer, "device", "cpu") == "cuda" and todo:
            batch = await sched.run(
                self._timed(lambda: cache.render_many([c.tf for c in todo])), BATCH
            )
            self._images.update({c.id: img for c, img in zip(todo, batch, strict=True)})
        images = []
        for c in candidates:
            job = self._timed(functools.partial(self.image, c.id, c.tf))
            images.append(await sched.run(job, BATCH))
        self.events.emit("rendered", generation=g, candidates=ids)
        return images

    async def _judge(
        self, g: int, candidates: list[Any], images: list[np.ndarray], base_cost: Cost
    ) -> Any:
        """The generation's Swiss tournament (seeded by the run and the generation, so a
        replay asks the same questions); a stopped tournament's partial cost is journaled."""
        from intuitf.evaluator.tournament import SwissTournament

        ids = [c.id for c in candidates]
        stage_aspects = getattr(self.explorer, "aspects", None) or {
            "initialize": "quality",
            "customize": "intent",
            "refine": "edit",
        }.get(self.stage, "quality")
        aspects = _aspects_for_stage(stage_aspects, self.intent)
        prior = {cid: self.ratings[cid] for cid in ids if cid in self.ratings}
        tournament = SwissTournament(
            self._tournament_judge(),
            aspects,
            self._judged_intent(),
            seed=_generation_seed(self.settings.seed, g),
            protocol=self.settings.protocol,  # type: ignore[arg-type]  # checked by RunSettings
        )
        history = self._faded_games(g) + self._verdicts.games(self.stage_index)

        def on_match(m: Any) -> None:
            v = m.verdict
            self.events.emit(
                "match_judged",
                generation=g,
                round=m.round,
                first=m.first,
                second=m.second,
                winner=v.overall.value,
                p_first=v.p_first,
                per_aspect={k: c.value for k, c in v.per_aspect.items()},
                reasons=dict(v.rationale),
                cost=v.cost.to_dict(),
                cached=v.cached,
                error=v.error,
            )

        try:
            return await tournament.run(
                images, ids, prior=prior or None, history=history, on_match=on_match
            )
        except (BudgetExhausted, JudgeError, RunCancelled) as exc:
            partial = getattr(exc, "partial", None)
            if partial is not None:
                self.cost = _paid(self.judge, base_cost + partial.cost, self.run_dir)
                self._journal(
                    {
                        "type": "partial",
                        "generation": g,
                        "reason": type(exc).__name__,
                        "tournament": _safe_dict(partial),
                    }
                )
            raise

    def _faded_games(self, generation: int) -> list[tuple[str, str, float, float]]:
        """The stage's verdicts weighted for the fit of ``generation``: earlier generations'
        fade, unless the judge is deterministic (no lucky wins to forget)."""
        fade = 1.0 if getattr(self.judge, "deterministic", False) else HISTORY_FADE
        return faded(self.stage_games, generation, fade)

    def _tell(self, candidates: list[Any], result: Any) -> tuple[list[str], dict[str, float]]:
        """The generation's ranking (the model's, refit with a person's verdicts of this
        stage when there are any), told to the Explorer."""
        ids = [c.id for c in candidates]
        g = self.generation
        self.stage_games = self.stage_games + [
            (m.first, m.second, float(m.verdict.p_first), g) for m in result.matches
        ]
        ranking, ratings = self._verdicts.rank_generation(
            self.explorer.state_dict(),
            ids,
            list(result.ranking),
            {cid: float(result.ratings[cid]) for cid in ids},
            self._faded_games(g),
            self.stage_index,
        )
        # Fitness comes from the ranking and the stage's pressure schedule.
        self.explorer.tell(ranking)
        return ranking, ratings

    def _record(
        self,
        g: int,
        t0: float,
        candidates: list[Any],
        result: Any,
        base_cost: Cost,
        ranking: list[str],
        ratings: dict[str, float],
    ) -> GenerationRecord:
        """Account, journal and checkpoint generation ``g``; move to the next (and to the next
        stage when this one is done); announce it."""
        ids = [c.id for c in candidates]
        seconds = time.perf_counter() - t0
        self.cost = _paid(self.judge, base_cost + result.cost, self.run_dir)
        self.cost.seconds = base_cost.seconds + seconds
        self.ratings = ratings
        self.last_ranking = ranking
        rank_of = {cid: i + 1 for i, cid in enumerate(ranking)}
        cand_records = [
            {
                "id": c.id,
                "tf": c.tf.to_dict(),
                "rating": self.ratings[c.id],
                "rank": rank_of[c.id],
                "origin": c.origin,
                "parents": list(c.parents),
            }
            for c in candidates
        ]
        stats = _match_stats(result.matches)
        record = GenerationRecord(
            generation=g,
            stage=self.stage,
            ranking=list(ranking),
            ratings=dict(self.ratings),
            candidates=cand_records,
            cost=result.cost,
            seconds=seconds,
            match_stats=stats,
        )
        self.records.append(record)
        self.generation_seconds.append(seconds)
        self._journal(
            {
                "type": "generation",
                "generation": g,
                "stage": self.stage,
                "candidates": cand_records,
                "best_id": record.best_id,
                "rounds": result.rounds,
                **self._paid_this_generation(result.cost),
                "cached_calls": result.cost.cached_calls,
                "failed_calls": result.cost.failed_calls,
                "seconds": seconds,
                "match_stats": stats,
                "decided": stats["decided"],
                "undecided": stats["undecided"],
                "retried": stats["retried"],
                "indistinct": bool(stats["indistinct"]),
                "matches": [_match_dict(m) for m in result.matches],
            }
        )
        self._write_generation_pictures(g, candidates, ranking)
        keep = set(ids)
        self._images = {k: v for k, v in self._images.items() if k in keep}
        self.tfs = {k: v for k, v in self.tfs.items() if k in keep}

        self.generation += 1
        new_stage = None
        if self.generation >= self._stage_end() and self.stage_index + 1 < len(self.plan):
            self.stage_games = []  # other aspects: earlier verdicts answer another question
            self.stage_index += 1
            new_stage = self.plan[self.stage_index]
            self.explorer.set_stage(new_stage[0], generations=new_stage[1])
            self._journal({"type": "stage", "generation": self.generation, "stage": new_stage[0]})
        self._checkpoint()
        self.events.emit(
            "generation_ended",
            generation=g,
            stage=record.stage,
            ranking=ranking,
            ratings=self.ratings,
            best=ranking[0],
            cost=self.cost.to_dict(),
            generation_cost=result.cost.to_dict(),
            seconds=seconds,
            match_stats=stats,
        )
        if new_stage is not None:
            self.events.emit(
                "stage_started",
                stage=new_stage[0],
                generations=new_stage[1],
                generation=self.generation,
            )
        return record

    async def arun(self, *, write_outputs: bool = True) -> RunOutcome:
        """Run generations until the plan is done or something stops the run cleanly.

        Never raises for budget, model-server, disk, cancel or interrupt conditions: the
        outcome says why the run ended, and everything paid for is kept in the run folder.
        """
        reason, message = "completed", "All generations done."
        self.events.emit(
            "run_started",
            generation=self.generation,
            plan=[list(p) for p in self.plan],
            judge=_judge_name(self.judge),
            population=self.settings.population,
            volume=self.volume.name,
        )
        try:
            while not self.done:
                await self.astep()
        except BudgetExhausted as exc:
            reason, message = "budget", str(exc)
        except JudgeError as exc:
            reason, message = "judge", str(exc)
        except RunCancelled:
            reason, message = (
                "cancelled",
                "Cancelled; the generation in progress is replayed on resume.",
            )
        except (KeyboardInterrupt, asyncio.CancelledError):
            reason, message = "interrupted", "Interrupted by the user."
        except StorageError as exc:  # the run folder cannot be written (full disk, ...)
            reason, message = "storage", str(exc)
        return self._finish(reason, message, write_outputs)

    def _finish(self, reason: str, message: str, write_outputs: bool) -> RunOutcome:
        try:
            self._journal(
                {
                    "type": "end",
                    "generation": self.generation,
                    "reason": reason,
                    "message": message,
                    "cost": self.cost.to_dict(),
                }
            )
            if self.run_dir is not None and write_outputs and self.last_ranking:
                self.write_outputs()
        except IntuitfError as exc:  # e.g. the disk filled up while saving outputs
            reason, message = "storage", f"{message} Saving outputs failed: {exc}"
        self._ended = reason
        self._refresh("ended")
        self.events.emit("run_ended", reason=reason, message=message, cost=self.cost.to_dict(),
                         generation=self.generation)  # fmt: skip
        return RunOutcome(
            reason=reason,
            message=message,
            generations_done=self.generation,
            cost=self.cost,
            run_dir=self.run_dir.root if self.run_dir else None,
            best=self.best(self.settings.top_k),
        )

    def step(self) -> GenerationRecord:
        """:meth:`astep` for scripts (not inside a running event loop)."""
        return self._run_async(self.astep())

    def run(self, *, write_outputs: bool = True) -> RunOutcome:
        """:meth:`arun` for scripts (not inside a running event loop)."""
        try:
            return self._run_async(self.arun(write_outputs=write_outputs))
        except KeyboardInterrupt:
            return self._finish("interrupted", "Interrupted by the user.", write_outputs)

    # -- outputs --------------------------------------------------------------------------
    def write_outputs(self) -> None:
        """Best renderings, TF JSON, plots, exports, evolution plot and the HTML report."""
        from intuitf.session.outputs import write_run_outputs

        if self.run_dir is not None:
            write_run_outputs(self)

    # -- internals ------------------------------------------------------------------------
    def _run_async(self, coro: Coroutine[Any, Any, T]) -> T:
        try:
            asyncio.get_running_loop()
        except RuntimeError:
            pass
        else:
            coro.close()
            raise SessionError(
                "step() and run() cannot be called inside a running event loop.",
                "Use `await session.astep()` or `await session.arun()` there.",
            )
        if self._loop is None or self._loop.is_closed():
            self._loop = asyncio.new_event_loop()
        try:
            return self._loop.run_until_complete(coro)
        except BaseException:
            # Ctrl-C (or any abort) leaves the round's other requests pending: cancel them
            # and let them unwind, so nothing is left half-started (unanswered requests
            # were not paid for; answered ones are already in the verdict store).
            self._cancel_pending()
            raise

    def _cancel_pending(self) -> None:
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        pending = [t for t in asyncio.all_tasks(loop) if not t.done()]
        for t in pending:
            t.cancel()
        if pending:
            try:
                loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            except BaseException:  # a second Ctrl-C while unwinding: stop unwinding
                pass

    async def aclose(self) -> None:
        """Release the judge's connections and the run folder's lock (async callers)."""
        aclose = getattr(self.judge, "aclose", None)
        if aclose is not None:
            try:
                await aclose()
            except Exception:  # closing must never hide the run's own outcome
                pass
        self._release()

    def close(self) -> None:
        """Release the session's event loop, the judge's connections and the folder's lock."""
        loop, self._loop = self._loop, None
        if loop is not None and not loop.is_closed():
            aclose = getattr(self.judge, "aclose", None)
            if aclose is not None:
                try:
                    loop.run_until_complete(aclose())
                except Exception:  # closing must never hide the run's own outcome
                    pass
            loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()
        self._release()

    def _release(self) -> None:
        lock, self._lock = self._lock, None
        if lock is not None:
            lock.release()

    def __enter__(self) -> Session:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _journal(self, entry: dict) -> None:
        self.recorder.journal(entry)

    def _checkpoint(self) -> None:
        state = {
            "generation": self.generation,
            "stage_index": self.stage_index,
            "explorer": self.explorer.state_dict(),
            "cost": self.cost.to_dict(),
            "ratings": self.ratings,
            "ranking": self.last_ranking,
            "tfs": {k: v.to_dict() for k, v in self.tfs.items()},
            "stage_games": [list(g) for g in self.stage_games],
            "plan": [list(p) for p in self.plan],
            **self._verdicts.state(),
            "queries": self.queries,
            "understood": self.understood,
        }
        if self._current_intent_record is not None:
            state["intent"] = self._current_intent_record
        self.recorder.checkpoint(self.generation, state)
        self._paid_at_checkpoint = Cost(**self.cost.to_dict())

    def _restore(self, ckpt: dict[str, Any]) -> None:
        """What a checkpoint holds beyond the constructor's arguments: the verdict loop's
        state, the current question, and what was paid when it was written (the store may hold
        more: a killed attempt at the next generation, which that generation's journal entry
        counts)."""
        self._verdicts.restore(ckpt)
        if ckpt.get("intent"):
            self._current_intent_record = ckpt["intent"]
        self._paid_at_checkpoint = Cost(**ckpt.get("cost", {}))

    def _paid_this_generation(self, judged: Cost) -> dict:
        """The journal's figures of the generation just judged: everything paid since the last
        checkpoint (what an attempt killed before its checkpoint paid, and its requests in
        flight, included), so the journal adds up to the run's spend. Without a verdict store
        to count from, what the tournament itself paid."""
        if self.run_dir is None:
            paid = judged
        else:
            base = self._paid_at_checkpoint
            paid = Cost(
                calls=max(0, self.cost.calls - base.calls),
                input_tokens=max(0, self.cost.input_tokens - base.input_tokens),
                output_tokens=max(0, self.cost.output_tokens - base.output_tokens),
                usd=max(0.0, self.cost.usd - base.usd),
            )
        return {
            "calls": paid.calls,
            "input_tokens": paid.input_tokens,
            "output_tokens": paid.output_tokens,
            "cost_usd": paid.usd,
        }

    def _write_generation_pictures(self, g: int, candidates: list[Any], ranking: list[str]) -> None:
        if not self.recorder.keeps_pictures:
            return
        from intuitf.imageio import png_bytes, render_record
        from intuitf.plots import contact_sheet

        order = {cid: i for i, cid in enumerate(ranking)}
        ordered = sorted(candidates, key=lambda c: order[c.id])
        imgs = [self._images[c.id] for c in ordered]
        caps = [f"#{order[c.id] + 1} {c.id} {self.ratings[c.id]:.0f}" for c in ordered]
        sheet = contact_sheet(imgs, caps, columns=8)
        # The generation's best, small, for the history view.
        best = self._images[ordered[0].id]
        record = render_record(self.camera, (best.shape[1], best.shape[0]), self.volume.name,
                               shading=self.settings.shading)  # fmt: skip
        self.recorder.generation_pictures(g, png_bytes(sheet), png_bytes(best, record))


# -- helpers --------------------------------------------------------------------------------


# -- helpers -----------------------------------------------------------------------------
def _match_dict(m: Any) -> dict[str, Any]:
    if hasattr(m, "to_dict"):
        return m.to_dict()
    return dict(m.__dict__)


def _match_stats(matches: Sequence[Any]) -> dict[str, int]:
    """Matches decided, undecided (no usable answer) and asked more than once."""
    from intuitf.evaluator.tournament import MatchStats

    st = MatchStats.of(matches)
    # A decided match that came out a tie tells the candidates apart no more than none; when
    # every decided match is one, the judge could not tell this generation's candidates apart
    # ("indistinct": the run's summary, report and web app say so).
    ties = sum(1 for m in matches if m.verdict.decided and m.verdict.overall == "tie")
    return {"matches": st.matches, "decided": st.decided, "undecided": st.undecided,
            "retried": st.retried, "ties": ties,
            "indistinct": int(st.decided > 0 and ties == st.decided)}  # fmt: skip


def _safe_dict(result: Any) -> dict[str, Any]:
    try:
        return result.to_dict()
    except Exception:  # a partial result must never break saving the rest
        return {}
