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
import hashlib
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from intuitf.errors import BudgetExhausted, IntuitfError, JudgeError, RunCancelled, SessionError
from intuitf.evaluator.types import Aspect, Cost, Intent, Judge
from intuitf.session.events import EventLog
from intuitf.session.human import HumanVerdict, refit_ranking, stated_orders, weighted_games
from intuitf.session.records import GenerationRecord, RunOutcome, SessionSnapshot
from intuitf.session.rundir import RunDirectory
from intuitf.session.scheduler import BATCH, INTERACTIVE, render_scheduler
from intuitf.session.settings import RunSettings
from intuitf.session.spec import RunSpec, parse_spec
from intuitf.tf import GaussianTF
from intuitf.volume import Volume

__all__ = ["Session"]

#: Mean absolute difference (0-255 scale) under which two renderings count as the same picture.
_SAME_PICTURE = 1.0


def _generation_seed(seed: int, generation: int) -> int:
    """A per-generation seed for the tournament: independent of anything but the run seed."""
    h = hashlib.sha256(f"{seed}:{generation}".encode()).digest()
    return int.from_bytes(h[:4], "little")


def _palette_hint(intent: Intent, settings: RunSettings) -> list[tuple[float, float, float]]:
    """The colours the intent asks for, as a hint for the explorer (see ``RunSettings``)."""
    if not settings.palette_hint:
        return []
    from intuitf.evaluator.palette import intent_palette

    return intent_palette(intent, background=tuple(settings.background))


def _aspects_for_stage(stage_aspects: str, intent: Intent) -> list[Aspect]:
    from intuitf.evaluator.aspects import aspects_for, aspects_for_intent

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

    async def compare(self, first, second, aspects, intent):
        await self._session._gate()
        return await self._judge.compare(first, second, aspects, intent)

    def __getattr__(self, name: str):
        return getattr(self._judge, name)


class Session:
    """An optimisation run over one volume, one judging camera and an intent.

    Build one with :meth:`open` (a spec), :meth:`resume` (a run folder), :meth:`branch`, or
    :meth:`create` (in-memory objects; ``run_dir=None`` keeps everything in memory).
    """

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
        stage_games: Sequence[Sequence] = (),
        plan: Sequence[Sequence] | None = None,
        spec: RunSpec | None = None,
        human: Sequence[HumanVerdict] = (),
        pre_tell: dict | None = None,
        queries: int = 0,
        lock: Any = None,
    ) -> None:
        from intuitf.render import Camera, VolumeRenderer
        from intuitf.session.views import ViewRenderer

        self.volume = volume
        self.intent = intent
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
        self.ratings: dict[str, float] = dict(ratings or {})
        self.last_ranking: list[str] = list(last_ranking or [])
        self.tfs: dict[str, GaussianTF] = dict(population_tfs or {})
        #: The current stage's model verdicts so far, (first id, second id, score of first):
        #: the tournament fits them with each new generation's, so survivors keep their evidence.
        self.stage_games: list[tuple[str, str, float]] = [
            (str(a), str(b), float(s)) for a, b, s in stage_games
        ]
        #: Every verdict a person gave in this run (undone ones stay, marked).
        self.human: list[HumanVerdict] = list(human)
        #: The Explorer's state before the last ``tell``: a person's verdict re-tells it.
        self._pre_tell = pre_tell
        #: The verdicts the last generation was ranked with, and its stage (a stage change
        #: resets ``stage_games``; a person may still judge the last generation's gallery).
        self._judged_games: list[tuple[str, str, float]] = list(self.stage_games)
        self._judged_stage = stage_index
        self.queries = int(queries)
        self.camera = Camera.from_dict(settings.camera) if settings.camera else Camera()
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
        self._cache = None
        self._images: dict[str, np.ndarray] = {}
        self.records: list[GenerationRecord] = []
        self.generation_seconds: list[float] = []
        self.events = EventLog(self.name, run_dir.root / "events.jsonl" if run_dir else None)
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
        self._refresh()

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        spec: RunSpec | dict,
        run_dir: str | Path | None,
        *,
        overwrite: bool = False,
        judge: Judge | None = None,
        volume: Volume | None = None,
    ) -> Session:
        """Start the run ``spec`` describes in ``run_dir`` (None: in memory).

        Builds the volume, the judge (with its verdict store in the run folder and its
        budget), the intent (its pictures copied into the run folder) and the Explorer. A
        ``judge`` or ``volume`` given here is used instead of building one (tests, notebooks).
        """
        from intuitf.session.building import build_judge, copy_intent_pictures, load_intent
        from intuitf.session.lock import RunLock

        spec = parse_spec(spec)
        settings = spec.run_settings()
        rd = RunDirectory(run_dir) if run_dir is not None else None
        lock = None
        created = False
        if rd is not None:
            if rd.exists() and not overwrite:
                raise SessionError(
                    f"{rd.root} already holds a run.",
                    f"Continue it with --resume {rd.root}, or pick another folder "
                    "(-o) or --overwrite.",
                )
            created = not rd.root.exists()
            rd.root.mkdir(parents=True, exist_ok=True)
            lock = RunLock(rd.root)
            lock.acquire()
        try:
            vol = volume if volume is not None else spec.volume.load()
            if rd is not None:
                spec = copy_intent_pictures(spec, rd.root)
            intent = load_intent(spec.intent, rd.root if rd is not None else None)
            initial = [GaussianTF.from_dict(d) for d in spec.initial]
            if judge is None:
                judge = build_judge(spec.judge, rd.root if rd else None, settings.protocol)
            if spec.intent.kind == "edit":
                if len(initial) != 1:
                    raise SessionError(
                        "A refinement starts from exactly one transfer function.",
                        "Give the TF to refine as the spec's only 'initial' entry.",
                    )
                sess = cls._refine_from(
                    vol, initial[0], intent, judge, settings, rd, spec, overwrite, lock
                )
            else:
                sess = cls._new(vol, intent, judge, settings, rd, initial, overwrite, spec, lock)
        except BaseException:
            if lock is not None:
                lock.release()
            if created and rd is not None and not rd.exists():
                import shutil

                shutil.rmtree(rd.root, ignore_errors=True)
            raise
        return sess

    @classmethod
    def create(
        cls,
        volume: Volume,
        *,
        intent: Intent | None = None,
        judge: Judge | None = None,
        settings: RunSettings | None = None,
        run_dir: str | Path | None = None,
        initial: Sequence[GaussianTF] = (),
        overwrite: bool = False,
        spec: RunSpec | None = None,
    ) -> Session:
        """Start a new run from in-memory objects. ``initial`` TFs join the first population."""
        from intuitf.session.lock import RunLock

        intent = intent or Intent()
        settings = settings or RunSettings()
        settings.validate()
        if judge is None:
            from intuitf.evaluator.metric import MetricJudge

            judge = MetricJudge()
        rd = RunDirectory(run_dir) if run_dir is not None else None
        lock = None
        if rd is not None:
            rd.root.mkdir(parents=True, exist_ok=True)
            lock = RunLock(rd.root)
            lock.acquire()
        try:
            return cls._new(
                volume, intent, judge, settings, rd, list(initial), overwrite, spec, lock
            )
        except BaseException:
            if lock is not None:
                lock.release()
            raise

    @classmethod
    def _new(cls, volume, intent, judge, settings, rd, initial, overwrite, spec, lock) -> Session:
        from intuitf.explorer import make_explorer

        settings.validate()
        plan = settings.stage_plan(intent.kind != "none")
        counts, _ = volume.histogram()
        explorer = make_explorer(
            settings.explorer,
            population=settings.population,
            n_gaussians=settings.n_gaussians,
            generations=plan[0][1],
            stage=plan[0][0],
            seed=settings.seed,
            histogram=counts,
            value_range=volume.value_range,
            initial=list(initial),
            palette=_palette_hint(intent, settings),
        )
        if plan[0][0] == "refine":
            if len(initial) != 1 or not intent.selected:
                raise SessionError(
                    "Refinement starts from one transfer function and needs the Gaussians to change.",
                    "Give exactly one TF to refine and select at least one of its Gaussians.",
                )
            try:
                explorer.set_stage(
                    "refine", generations=plan[0][1], selected=intent.selected, base=initial[0]
                )
            except ValueError as exc:
                raise SessionError(f"Cannot refine: {exc}") from exc
        if rd is not None:
            rd.create(overwrite=overwrite)
            spec = _spec_for_record(spec, intent, settings, initial, judge, rd)
            from intuitf.session.building import redacted

            rd.write_run(
                {
                    "spec": redacted(spec).to_dict(),
                    "volume": volume.summary(),
                    "intent": _intent_record(intent),
                    "judge": _judge_name(judge),
                    "judges": [{"judge": _judge_name(judge), "from_generation": 0}],
                    "settings": settings.to_dict(),
                    "plan": [list(p) for p in plan],
                    "initial": [tf.to_dict() for tf in initial],
                    "parent": spec.parent.model_dump() if spec.parent else None,
                    "versions": _versions(),
                    "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                }
            )
            rd.append_journal({"type": "stage", "generation": 0, "stage": plan[0][0]})
        sess = cls(
            volume,
            intent=intent,
            judge=judge,
            settings=settings,
            run_dir=rd,
            explorer=explorer,
            spec=spec,
            lock=lock,
        )
        sess.events.emit("stage_started", stage=plan[0][0], generations=plan[0][1], generation=0)
        return sess

    @classmethod
    def refine(
        cls,
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
    ) -> Session:
        """A run of the refine stage: only the Gaussians ``selected`` (indices into ``tf``) change.

        The judge sees the rendering before the edit and ``instruction``, and prefers
        candidates where the change happened in the selected features and the rest is kept.
        """
        intent = Intent(
            kind="edit", text=instruction, selected=tuple(int(i) for i in selected), about=about
        )
        if judge is None:
            from intuitf.evaluator.metric import MetricJudge

            judge = MetricJudge()
        rd = RunDirectory(run_dir) if run_dir is not None else None
        lock = None
        if rd is not None:
            from intuitf.session.lock import RunLock

            rd.root.mkdir(parents=True, exist_ok=True)
            lock = RunLock(rd.root)
            lock.acquire()
        try:
            return cls._refine_from(
                volume, tf, intent, judge, settings or RunSettings(), rd, None, overwrite, lock
            )
        except BaseException:
            if lock is not None:
                lock.release()
            raise

    @classmethod
    def _refine_from(cls, volume, tf, intent, judge, settings, rd, spec, overwrite, lock):
        from dataclasses import replace

        from intuitf.render import Camera, VolumeRenderer

        if not settings.stages or settings.stages[0][0] != "refine":
            settings.stages = [("refine", settings.generations)]
        camera = Camera.from_dict(settings.camera) if settings.camera else Camera()
        if intent.base is None:
            base = VolumeRenderer(
                volume,
                size=settings.image_size,
                shading=settings.shading,
                background=tuple(settings.background),
            ).render(tf, camera)
            intent = replace(intent, base=base)
        return cls._new(volume, intent, judge, settings, rd, [tf], overwrite, spec, lock)

    @classmethod
    def resume(
        cls,
        run_dir: str | Path,
        volume: Volume | None = None,
        judge: Judge | None = None,
        *,
        evaluator: str | None = None,
        base_url: str | None = None,
        budget_usd: float | None = None,
        budget_calls: int | None = None,
        judge_options: dict | None = None,
    ) -> Session:
        """Continue the run in ``run_dir`` from its last checkpoint.

        The volume and the judge are rebuilt from the run's spec unless given. ``evaluator``
        and ``base_url`` move the run to another model or server (recorded in ``run.json``);
        the budgets replace the run's and count everything the run already paid.
        """
        from intuitf.explorer import explorer_from_state
        from intuitf.session.building import build_judge, load_intent, redacted, spec_of_record
        from intuitf.session.lock import RunLock

        rd = RunDirectory(run_dir)
        record = rd.read_run()
        lock = RunLock(rd.root)
        lock.acquire()
        try:
            spec = spec_of_record(record)
            settings = RunSettings.from_dict(record["settings"])
            spec, moved = _moved_spec(spec, evaluator, base_url, budget_usd, budget_calls,
                                      judge_options, judge is None)  # fmt: skip
            ckpt = rd.read_checkpoint()
            vol = volume if volume is not None else spec.volume.load()
            if judge is None:
                judge = build_judge(spec.judge, rd.root, settings.protocol)
            generation = int(ckpt["generation"]) if ckpt else 0
            stored = redacted(spec).to_dict()
            if moved or stored != record.get("spec"):
                record["spec"] = stored
                judges = record.setdefault("judges", [])
                if moved:
                    judges.append({"judge": _judge_name(judge), "from_generation": generation})
                    record["judge"] = _judge_name(judge)
                rd.write_run(record)
            if ckpt and ckpt.get("intent"):
                intent = load_intent(_intent_spec(ckpt["intent"]), rd.root)
            else:
                intent = load_intent(spec.intent, rd.root)
            if ckpt is None:
                # Stopped before the first generation finished: start over, same seed; the
                # verdict store still holds whatever was paid for.
                initial = [GaussianTF.from_dict(d) for d in spec.initial]
                sess = cls._new(vol, intent, judge, settings, None, initial, False, spec, lock)
                sess.run_dir = rd
                sess.name = rd.root.name
                sess.events = EventLog(sess.name, rd.events)
                sess.cost = _paid(judge, sess.cost, rd)
                sess.judge_moved = moved
                sess._refresh()
                if moved:
                    sess._journal({"type": "judge", "generation": 0, "judge": _judge_name(judge)})
                return sess
            sess = cls(
                vol,
                intent=intent,
                judge=judge,
                settings=settings,
                run_dir=rd,
                explorer=explorer_from_state(ckpt["explorer"]),
                stage_index=int(ckpt["stage_index"]),
                generation=generation,
                cost=_paid(judge, Cost(**ckpt.get("cost", {})), rd),
                ratings={k: float(v) for k, v in ckpt.get("ratings", {}).items()},
                last_ranking=list(ckpt.get("ranking", [])),
                population_tfs={k: GaussianTF.from_dict(v) for k, v in ckpt.get("tfs", {}).items()},
                stage_games=ckpt.get("stage_games", []),
                plan=ckpt.get("plan"),
                spec=spec,
                human=[HumanVerdict.from_dict(h) for h in ckpt.get("human", [])],
                pre_tell=ckpt.get("pre_tell"),
                queries=int(ckpt.get("queries", 0)),
                lock=lock,
            )
            sess._model_ranking = ckpt.get("model_ranking")
            sess._model_ratings = ckpt.get("model_ratings")
            if "judged_games" in ckpt:
                sess._judged_games = [tuple(g) for g in ckpt["judged_games"]]
                sess._judged_stage = int(ckpt.get("judged_stage", sess.stage_index))
            if ckpt.get("intent"):
                sess._current_intent_record = ckpt["intent"]
            sess.judge_moved = moved
            if moved:
                sess._journal(
                    {"type": "judge", "generation": generation, "judge": _judge_name(judge)}
                )
            return sess
        except BaseException:
            lock.release()
            raise

    @classmethod
    def branch(
        cls,
        parent_dir: str | Path,
        run_dir: str | Path,
        *,
        generation: int | None = None,
        candidate: str | None = None,
        changes: dict | None = None,
        judge: Judge | None = None,
        volume: Volume | None = None,
    ) -> Session:
        """A new run that starts where ``parent_dir``'s run was at ``generation``, or from its
        ``candidate`` (an id like ``g003-007``), with ``changes`` to its spec (plain data,
        merged field by field: a new intent, judge, settings, ...).

        From a generation with an unchanged spec, the branch reproduces the parent's run from
        there: the Explorer's state, the stage, the ratings and the verdicts are the parent's
        at that point. From a candidate, the candidate joins a fresh first population (as
        ``--start-from`` does) and the branch starts its own plan.
        """
        from intuitf.session.building import spec_of_record
        from intuitf.session.spec import ParentLink

        parent = RunDirectory(parent_dir)
        record = parent.read_run()
        base = spec_of_record(record).to_dict()
        for key, value in (changes or {}).items():
            if isinstance(value, dict) and isinstance(base.get(key), dict) and key != "intent":
                base[key] = {**base[key], **value}
            else:
                base[key] = value
        for name in ("reference", "sketch", "base"):  # the parent's copies, by full path
            path = (base.get("intent") or {}).get(name)
            if path and not Path(path).is_absolute() and (parent.root / path).exists():
                base["intent"][name] = str(parent.root / path)
        link = {"run": str(parent.root), "generation": generation, "candidate": candidate}
        if candidate is not None:
            tf = _candidate_tf(parent, candidate)
            base["initial"] = [tf.to_dict()]
            if (base.get("intent") or {}).get("kind") == "edit":
                link["selected"] = list(base["intent"].get("selected", []))
        base["parent"] = link
        spec = parse_spec(base)
        if generation is None or generation == 0 or candidate is not None:
            return cls.open(spec, run_dir, judge=judge, volume=volume)
        ckpt_path = parent.generation_checkpoint(generation)
        if not ckpt_path.exists():
            raise SessionError(
                f"{parent.root} has no saved state for generation {generation}.",
                "Branch from a generation the run has finished (see its history).",
            )
        ParentLink.model_validate(link)
        sess = cls.open(spec, run_dir, judge=judge, volume=volume)
        # Take over the parent's state at that generation, then continue as a resume would.
        import json

        state = json.loads(ckpt_path.read_text(encoding="utf-8"))
        state["cost"] = Cost().to_dict()  # the branch pays only for what it asks itself
        assert sess.run_dir is not None
        sess.run_dir.write_checkpoint(state)
        rd_root, judge_used, vol = sess.run_dir.root, sess.judge, sess.volume
        sess.close()
        return cls.resume(rd_root, vol, judge_used)

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
    def judge_name(self) -> str:
        """The judge's name, with any credentials in a URL redacted."""
        return _judge_name(self.judge)

    @property
    def lock(self):
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
            plan=tuple(tuple(p) for p in self.plan),
            ranking=tuple(self.last_ranking),
            ratings=MappingProxyType(dict(self.ratings)),
            tfs=MappingProxyType(dict(self.tfs)),
            cost=Cost(**self.cost.to_dict()),
            last_seq=self.events.last_seq,
            ended=self._ended,
        )

    def _stage_end(self) -> int:
        return sum(n for _, n in self.plan[: self.stage_index + 1])

    def sample_cache(self):
        """The sample cache for the judging camera (built on first use)."""
        if self._cache is None:
            self._cache = self.renderer.sample_cache(self.camera)
        return self._cache

    def set_camera(self, camera) -> None:
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

    def image(self, candidate_id: str, tf: GaussianTF) -> np.ndarray:
        """The judging rendering of a candidate, rendered once and remembered."""
        img = self._images.get(candidate_id)
        if img is None:
            img = self.sample_cache().render(tf)
            self._images[candidate_id] = img
        return img

    def render(
        self, tf: GaussianTF, *, size: int | None = None, camera=None, shading: bool | None = None
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

        While a generation is being judged, the verdict waits for that generation's end.
        """
        if not self._stepping and self.last_ranking and self._pre_tell is not None:
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

        ids = list(self.last_ranking)
        model_ranking = list(self._model_ranking or ids)
        human = self._human_games(self._judged_stage)
        if human:
            ranking, ratings = refit_ranking(
                ids,
                self._judged_games + human,
                tiebreak=model_ranking,
                stated=stated_orders(self.human, self._judged_stage),
            )
        else:
            ranking, ratings = model_ranking, dict(self._model_ratings or self.ratings)
        palette = getattr(self.explorer, "palette", None)
        self.explorer = explorer_from_state(self._pre_tell)
        self.explorer.tell(ranking)
        if self.stage_index != self._judged_stage:  # the stage changed after that generation
            stage, n = self.plan[self.stage_index]
            self.explorer.set_stage(stage, generations=n)
            if palette is not None:
                self.explorer.palette = palette
        self.last_ranking, self.ratings = ranking, ratings

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

    # -- the loop -------------------------------------------------------------------------
    async def astep(self) -> GenerationRecord:
        """Run one generation: ask, render, judge, tell, journal, checkpoint."""
        from intuitf.evaluator.tournament import SwissTournament

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
            candidates = self.explorer.ask()
            self.events.emit(
                "generation_started", generation=g, stage=self.stage, population=len(candidates)
            )
            ids = [c.id for c in candidates]
            for c in candidates:
                self.tfs[c.id] = c.tf
            sched = render_scheduler()
            await sched.run(self.sample_cache, BATCH)
            images = []
            for c in candidates:  # one job each, so interactive renders can go between them
                images.append(await sched.run(lambda c=c: self.image(c.id, c.tf), BATCH))
            self.events.emit("rendered", generation=g, candidates=ids)

            stage_aspects = getattr(self.explorer, "aspects", None) or {
                "initialize": "quality",
                "customize": "intent",
                "refine": "edit",
            }.get(self.stage, "quality")
            aspects = _aspects_for_stage(stage_aspects, self.intent)
            prior = {cid: self.ratings[cid] for cid in ids if cid in self.ratings}
            tournament = SwissTournament(
                _GatedJudge(self, self.judge),
                aspects,
                self.intent,
                seed=_generation_seed(self.settings.seed, g),
                protocol=self.settings.protocol,
            )
            history = self.stage_games + self._human_games()
            base_cost = Cost(**self.cost.to_dict())

            def on_match(m) -> None:
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
                result = await tournament.run(
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

            # A person's verdicts of this stage join the fit; without any, the model's ranking
            # stands exactly as the tournament gave it.
            self._pre_tell = self.explorer.state_dict()
            self._model_ranking = list(result.ranking)
            self._model_ratings = {cid: float(result.ratings[cid]) for cid in ids}
            self.stage_games = self.stage_games + [
                (m.first, m.second, float(m.verdict.p_first)) for m in result.matches
            ]
            self._judged_games, self._judged_stage = list(self.stage_games), self.stage_index
            human = self._human_games()
            if human:
                ranking, ratings = refit_ranking(
                    ids,
                    self.stage_games + human,
                    tiebreak=list(result.ranking),
                    stated=stated_orders(self.human, self.stage_index),
                )
            else:
                ranking, ratings = list(result.ranking), dict(self._model_ratings)
            # Fitness comes from the ranking and the stage's pressure schedule.
            self.explorer.tell(ranking)
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
                    "calls": result.cost.calls,
                    "cached_calls": result.cost.cached_calls,
                    "failed_calls": result.cost.failed_calls,
                    "input_tokens": result.cost.input_tokens,
                    "output_tokens": result.cost.output_tokens,
                    "cost_usd": result.cost.usd,
                    "seconds": seconds,
                    "match_stats": stats,
                    "decided": stats["decided"],
                    "undecided": stats["undecided"],
                    "retried": stats["retried"],
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
                self._journal(
                    {"type": "stage", "generation": self.generation, "stage": new_stage[0]}
                )
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
        finally:
            self._stepping = False
            self._refresh("idle")

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
        except SessionError as exc:  # the run folder cannot be written (full disk, ...)
            reason, message = "storage", str(exc)
        return self._finish(reason, message, write_outputs)

    def _finish(self, reason: str, message: str, write_outputs: bool) -> RunOutcome:
        if self.run_dir is not None:
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
                if write_outputs and self.last_ranking:
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
    def _run_async(self, coro):
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
        if self.run_dir is not None:
            self.run_dir.append_journal(entry)

    def _checkpoint(self) -> None:
        if self.run_dir is None:
            return
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
            "human": [h.to_dict() for h in self.human],
            "pre_tell": self._pre_tell,
            "model_ranking": self._model_ranking,
            "model_ratings": self._model_ratings,
            "judged_games": [list(g) for g in self._judged_games],
            "judged_stage": self._judged_stage,
            "queries": self.queries,
        }
        if self._current_intent_record is not None:
            state["intent"] = self._current_intent_record
        self.run_dir.write_checkpoint(state)
        # Kept per generation too: a branch can start from any generation and reproduce it.
        self.run_dir.write_generation_checkpoint(self.generation, state)

    def _write_generation_pictures(self, g: int, candidates, ranking: list[str]) -> None:
        if self.run_dir is None:
            return
        from intuitf.imageio import png_bytes
        from intuitf.plots import contact_sheet
        from intuitf.session.rundir import atomic_write_bytes

        order = {cid: i for i, cid in enumerate(ranking)}
        ordered = sorted(candidates, key=lambda c: order[c.id])
        imgs = [self._images[c.id] for c in ordered]
        caps = [f"#{order[c.id] + 1} {c.id} {self.ratings[c.id]:.0f}" for c in ordered]
        sheet = contact_sheet(imgs, caps, columns=8)
        atomic_write_bytes(self.run_dir.generations_dir / f"gen{g:03d}.png", png_bytes(sheet))
        # The generation's best, small, for the history view.
        best = self._images[ordered[0].id]
        atomic_write_bytes(self.run_dir.generations_dir / f"gen{g:03d}-best.png", png_bytes(best))


# -- helpers --------------------------------------------------------------------------------
def _versions() -> dict:
    import platform

    import numba

    import intuitf

    return {
        "intuitf": intuitf.__version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
    }


def _judge_name(judge) -> str:
    name = getattr(judge, "name", type(judge).__name__)
    try:
        from intuitf.evaluator.providers import redact_url
    except ImportError:  # pragma: no cover - older evaluator without the helper
        return str(name)
    return redact_url(str(name))


def _paid(judge, cost: Cost, rd: RunDirectory | None) -> Cost:
    """``cost`` with calls, tokens and money as the run's verdict store recorded them (exact
    across resumes and kills), when the judge keeps its answers there."""
    from intuitf.evaluator.budget import run_spend, with_spend

    if rd is None:
        return cost
    return with_spend(cost, run_spend(judge, rd.verdicts))


def _intent_record(intent: Intent) -> dict:
    return {
        "kind": intent.kind,
        "text": intent.text,
        "about": intent.about,
        "selected": list(intent.selected),
        "has_reference": intent.reference is not None,
        "has_sketch": intent.sketch is not None,
        "has_base": intent.base is not None,
    }


def _intent_spec(rec: dict):
    from intuitf.session.spec import IntentSpec

    pictures = rec.get("pictures", {})
    return IntentSpec.model_construct(
        kind=rec.get("kind", "none"),
        text=rec.get("text"),
        about=rec.get("about"),
        selected=list(rec.get("selected", [])),
        reference=pictures.get("reference"),
        sketch=pictures.get("sketch"),
        base=pictures.get("base"),
    )


def _spec_for_record(spec, intent, settings, initial, judge, rd) -> RunSpec:
    """The spec to write into run.json: the given one, or one describing in-memory inputs."""
    from intuitf.session.building import intent_spec_of, save_intent_pictures
    from intuitf.session.spec import JudgeSpec

    pictures = save_intent_pictures(intent, rd.root)
    if spec is None:
        return RunSpec.model_construct(
            version=1,
            name=rd.root.name,
            volume=_volume_spec_unknown(),
            intent=intent_spec_of(intent, pictures),
            judge=JudgeSpec(
                spec=_judge_name(judge) if _judge_name(judge) != "metric" else "metric"
            ),
            settings=settings.to_dict(),
            initial=[tf.to_dict() for tf in initial],
            parent=None,
        )
    return spec.model_copy(
        update={
            "intent": intent_spec_of(intent, pictures),
            "settings": settings.to_dict(),
            "name": spec.name or rd.root.name,
        }
    )


def _volume_spec_unknown():
    from intuitf.session.spec import VolumeSpec

    # An in-memory volume has no source to reopen; resuming needs the volume passed in.
    return VolumeSpec.model_construct(source="", shape=None, dtype=None, byte_order=None,
                                      spacing=None, max_dim=None)  # fmt: skip


def _moved_spec(spec: RunSpec, evaluator, base_url, budget_usd, budget_calls, options, build):
    """The spec with a resume's judge changes applied, and whether the judge moved."""
    from intuitf.session.building import resumed_judge_spec

    moved = False
    if build and spec.judge.is_model or evaluator or base_url:
        judge_spec, moved = resumed_judge_spec(spec.judge, evaluator, base_url)
        spec = spec.model_copy(update={"judge": judge_spec})
    j = spec.judge
    update: dict[str, Any] = {}
    if budget_usd is not None:
        if budget_usd < 0:
            raise SessionError(f"A budget cannot be negative (got ${budget_usd}).")
        update["budget_usd"] = budget_usd
    if budget_calls is not None:
        if budget_calls < 0:
            raise SessionError(f"A budget cannot be negative (got {budget_calls} calls).")
        update["budget_calls"] = budget_calls
    if options:
        update["options"] = {**j.options, **options}
    if not update:
        return spec, moved
    return spec.model_copy(update={"judge": j.model_copy(update=update)}), moved


def _candidate_tf(rd: RunDirectory, candidate: str) -> GaussianTF:
    for entry in reversed(rd.generations()):
        for c in entry.get("candidates", []):
            if c.get("id") == candidate:
                return GaussianTF.from_dict(c["tf"])
    raise SessionError(
        f"No candidate {candidate!r} in {rd.root}.",
        "Use an id from the run's history, like g003-007.",
    )


def _match_dict(m) -> dict:
    if hasattr(m, "to_dict"):
        return m.to_dict()
    return dict(m.__dict__)


def _match_stats(matches) -> dict[str, int]:
    """Matches decided, undecided (no usable answer) and asked more than once."""
    from intuitf.evaluator.tournament import MatchStats

    st = MatchStats.of(matches)
    return {"matches": st.matches, "decided": st.decided, "undecided": st.undecided,
            "retried": st.retried}  # fmt: skip


def _safe_dict(result) -> dict:
    try:
        return result.to_dict()
    except Exception:  # a partial result must never break saving the rest
        return {}
