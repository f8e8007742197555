"""The Session: Trial (render) → Insight (judge) → Replanning (evolve), generation after generation.

A Session owns the loop, the stage plan (initialize → customize → refine), the run directory and
its journal. The command line, the web app and the Python API all drive this class; none of
them holds algorithm logic of its own.

Resuming: a checkpoint is written after every generation. A run that stopped for any reason
(crash, kill, Ctrl-C, budget, lost server, full disk) is continued with :meth:`Session.resume`.
The generation that was in flight is replayed: the Explorer state, the renderings and the
tournament's seed are the same, so the tournament asks the same questions, and the judge's
verdict cache answers every one that was already paid for. The resumed run therefore ends
with the same result as an uninterrupted one.
"""

from __future__ import annotations

import asyncio
import hashlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from intuitf.errors import BudgetExhausted, IntuitfError, JudgeError, SessionError
from intuitf.evaluator.types import Aspect, Cost, Intent, Judge
from intuitf.session.rundir import RunDirectory
from intuitf.session.settings import RunSettings
from intuitf.tf import GaussianTF
from intuitf.volume import Volume


@dataclass
class ProgressEvent:
    """What the session is doing, for progress displays (CLI bars, web streams)."""

    kind: str  # "generation_start" | "rendered" | "round" | "generation_end" | "end"
    generation: int
    generations: int
    stage: str
    round: int = 0
    rounds: int = 0
    cost: Cost = field(default_factory=Cost)
    seconds_per_generation: float | None = None
    message: str = ""


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

    @property
    def best_id(self) -> str:
        return self.ranking[0]


@dataclass
class RunOutcome:
    """How a run ended and where its results are."""

    reason: str  # "completed" | "budget" | "judge" | "interrupted" | "storage"
    message: str
    generations_done: int
    cost: Cost
    run_dir: Path | None
    best: list[tuple[GaussianTF, float]]

    @property
    def completed(self) -> bool:
        return self.reason == "completed"


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


class Session:
    """An optimisation run over one volume, one camera and one intent.

    Build one with :meth:`create` (a new run) or :meth:`resume` (continue a run folder);
    ``run_dir=None`` keeps everything in memory (handy in notebooks and tests).
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
    ) -> None:
        from intuitf.render import Camera, VolumeRenderer

        self.volume = volume
        self.intent = intent
        self.judge = judge
        self.settings = settings
        self.run_dir = run_dir
        self.explorer = explorer
        self.plan = settings.stage_plan(intent.kind != "none")
        self.stage_index = stage_index
        self.generation = generation
        self.cost = cost or Cost()
        self.ratings: dict[str, float] = dict(ratings or {})
        self.last_ranking: list[str] = list(last_ranking or [])
        self.tfs: dict[str, GaussianTF] = dict(population_tfs or {})
        #: The current stage's verdicts so far, (first id, second id, score of first): the
        #: tournament fits them with each new generation's, so survivors keep their evidence.
        self.stage_games: list[tuple[str, str, float]] = [
            (str(a), str(b), float(s)) for a, b, s in stage_games
        ]
        self.camera = Camera.from_dict(settings.camera) if settings.camera else Camera()
        self.renderer = VolumeRenderer(
            volume,
            size=settings.image_size,
            shading=settings.shading,
            background=tuple(settings.background),
        )
        self._cache = None
        self._images: dict[str, np.ndarray] = {}
        self._renderers: dict[tuple[int, bool], Any] = {}
        self.records: list[GenerationRecord] = []
        self.generation_seconds: list[float] = []
        # One event loop for the session's life: model clients keep connections bound to it.
        self._loop: asyncio.AbstractEventLoop | None = None

    # -- construction ---------------------------------------------------------------------
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
        extra_record: dict | None = None,
    ) -> Session:
        """Start a new run. ``initial`` TFs join the first population (branch from a result)."""
        from intuitf.explorer import make_explorer

        intent = intent or Intent()
        settings = settings or RunSettings()
        settings.validate()
        if judge is None:
            from intuitf.evaluator.metric import MetricJudge

            judge = MetricJudge()
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
        rd = RunDirectory(run_dir) if run_dir is not None else None
        if rd is not None:
            rd.create(overwrite=overwrite)
            _save_intent_images(rd, intent)
            rd.write_run(
                {
                    "volume": volume.summary(),
                    "intent": _intent_record(intent),
                    "judge": getattr(judge, "name", type(judge).__name__),
                    "settings": settings.to_dict(),
                    "plan": [list(p) for p in plan],
                    "initial": [tf.to_dict() for tf in initial],
                    "versions": _versions(),
                    "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                    **(extra_record or {}),
                }
            )
            rd.append_journal({"type": "stage", "generation": 0, "stage": plan[0][0]})
        return cls(
            volume, intent=intent, judge=judge, settings=settings, run_dir=rd, explorer=explorer
        )

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
        extra_record: dict | None = None,
    ) -> Session:
        """A run of the refine stage: only the Gaussians ``selected`` (indices into ``tf``) change.

        The judge sees the rendering before the edit and ``instruction``, and prefers
        candidates where the change happened in the selected features and the rest is kept.
        """
        from intuitf.render import Camera, VolumeRenderer

        settings = settings or RunSettings()
        settings.stages = [("refine", settings.generations)]
        camera = Camera.from_dict(settings.camera) if settings.camera else Camera()
        base = VolumeRenderer(
            volume,
            size=settings.image_size,
            shading=settings.shading,
            background=tuple(settings.background),
        ).render(tf, camera)
        intent = Intent(
            kind="edit",
            text=instruction,
            base=base,
            selected=tuple(int(i) for i in selected),
            about=about,
        )
        return cls.create(
            volume,
            intent=intent,
            judge=judge,
            settings=settings,
            run_dir=run_dir,
            initial=[tf],
            overwrite=overwrite,
            extra_record=extra_record,
        )

    @classmethod
    def resume(cls, run_dir: str | Path, volume: Volume, judge: Judge) -> Session:
        """Continue the run in ``run_dir`` from its last checkpoint."""
        from intuitf.explorer import explorer_from_state

        rd = RunDirectory(run_dir)
        record = rd.read_run()
        settings = RunSettings.from_dict(record["settings"])
        intent = _load_intent(rd, record.get("intent", {}))
        ckpt = rd.read_checkpoint()
        if ckpt is None:
            # Stopped before the first generation finished: start over, same seed; the
            # verdict cache still holds whatever was paid for.
            initial = [GaussianTF.from_dict(d) for d in record.get("initial", [])]
            sess = cls.create(
                volume, intent=intent, judge=judge, settings=settings, run_dir=None, initial=initial
            )
            sess.run_dir = rd
            return sess
        explorer = explorer_from_state(ckpt["explorer"])
        return cls(
            volume,
            intent=intent,
            judge=judge,
            settings=settings,
            run_dir=rd,
            explorer=explorer,
            stage_index=int(ckpt["stage_index"]),
            generation=int(ckpt["generation"]),
            cost=Cost(**ckpt.get("cost", {})),
            ratings={k: float(v) for k, v in ckpt.get("ratings", {}).items()},
            last_ranking=list(ckpt.get("ranking", [])),
            population_tfs={k: GaussianTF.from_dict(v) for k, v in ckpt.get("tfs", {}).items()},
            stage_games=ckpt.get("stage_games", []),
        )

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

    def _stage_end(self) -> int:
        return sum(n for _, n in self.plan[: self.stage_index + 1])

    def sample_cache(self):
        """The sample cache for the session's camera (built on first use)."""
        if self._cache is None:
            self._cache = self.renderer.sample_cache(self.camera)
        return self._cache

    def set_camera(self, camera) -> None:
        """Change the view; renderings are redone for the new camera."""
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
        """Render any TF with the session's volume (and camera unless given)."""
        from intuitf.render import VolumeRenderer

        size = size or self.settings.output_size
        shading = self.settings.shading if shading is None else shading
        if size == self.settings.image_size and camera is None and shading == self.settings.shading:
            return self.sample_cache().render(tf)
        # Kept per (size, shading): a renderer computes its volume's gradient once, and the
        # best TFs of a run are all rendered at the same output size.
        r = self._renderers.get((size, shading))
        if r is None:
            r = VolumeRenderer(
                self.volume, size=size, shading=shading, background=tuple(self.settings.background)
            )
            self._renderers[(size, shading)] = r
        return r.render(tf, camera or self.camera)

    def best(self, k: int = 1, distinct: bool = True) -> list[tuple[GaussianTF, float]]:
        """The top ``k`` TFs of the last judged generation, with their ratings.

        With ``distinct`` (the default), a TF whose rendering looks the same as that of one
        ranked above it (mean difference under 1/255, as when only a hidden feature differs)
        is passed over for the next one: k results are k different pictures.
        """
        out: list[tuple[GaussianTF, float]] = []
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
            out.append((tf, self.ratings.get(cid, float("nan"))))
        return out

    # -- the loop -------------------------------------------------------------------------
    def step(self, progress: Callable[[ProgressEvent], None] | None = None) -> GenerationRecord:
        """Run one generation: ask, render, judge, tell, journal, checkpoint."""
        from intuitf.evaluator.tournament import SwissTournament

        if self.done:
            raise SessionError("This run has already done all its generations.")
        t0 = time.perf_counter()
        g = self.generation
        emit = progress or (lambda e: None)
        emit(self._event("generation_start"))
        candidates = self.explorer.ask()
        ids = [c.id for c in candidates]
        for c in candidates:
            self.tfs[c.id] = c.tf
        images = [self.image(c.id, c.tf) for c in candidates]
        emit(self._event("rendered"))

        stage_aspects = getattr(self.explorer, "aspects", None) or {
            "initialize": "quality",
            "customize": "intent",
            "refine": "edit",
        }.get(self.stage, "quality")
        aspects = _aspects_for_stage(stage_aspects, self.intent)
        prior = {cid: self.ratings[cid] for cid in ids if cid in self.ratings}
        tournament = SwissTournament(
            self.judge,
            aspects,
            self.intent,
            seed=_generation_seed(self.settings.seed, g),
            protocol=self.settings.protocol,
        )

        def on_round(round_index, rounds, matches_done, cost):
            emit(self._event("round", round=round_index, rounds=rounds, cost=self.cost + cost))

        try:
            result = self._run_async(
                tournament.run(
                    images, ids, prior=prior or None, progress=on_round, history=self.stage_games
                )
            )
        except (BudgetExhausted, JudgeError) as exc:
            partial = getattr(exc, "partial", None)
            if partial is not None:
                self.cost += partial.cost
                self._journal(
                    {
                        "type": "partial",
                        "generation": g,
                        "reason": type(exc).__name__,
                        "tournament": _safe_dict(partial),
                    }
                )
            raise

        # Fitness comes from the ranking and the stage's pressure schedule (Explorer default).
        self.explorer.tell(result.ranking)
        seconds = time.perf_counter() - t0
        self.cost += result.cost
        self.cost.seconds += seconds
        self.ratings = {cid: float(result.ratings[cid]) for cid in ids}
        self.last_ranking = list(result.ranking)
        rank_of = {cid: i + 1 for i, cid in enumerate(result.ranking)}
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
        record = GenerationRecord(
            generation=g,
            stage=self.stage,
            ranking=list(result.ranking),
            ratings=dict(self.ratings),
            candidates=cand_records,
            cost=result.cost,
            seconds=seconds,
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
                "matches": [_match_dict(m) for m in result.matches],
            }
        )
        self._write_generation_sheet(g, candidates, result.ranking)
        # Forget images of candidates that left the population.
        keep = set(ids)
        self._images = {k: v for k, v in self._images.items() if k in keep}
        self.tfs = {k: v for k, v in self.tfs.items() if k in keep}
        self.stage_games.extend(
            (m.first, m.second, float(m.verdict.p_first)) for m in result.matches
        )

        self.generation += 1
        if self.generation >= self._stage_end() and self.stage_index + 1 < len(self.plan):
            self.stage_games = []  # other aspects: earlier verdicts answer another question
            self.stage_index += 1
            stage, n = self.plan[self.stage_index]
            self.explorer.set_stage(stage, generations=n)
            self._journal({"type": "stage", "generation": self.generation, "stage": stage})
        self._checkpoint()
        emit(self._event("generation_end"))
        return record

    def run(
        self, progress: Callable[[ProgressEvent], None] | None = None, *, write_outputs: bool = True
    ) -> RunOutcome:
        """Run generations until the plan is done or something stops the run cleanly.

        Never raises for budget, model-server, disk or interrupt conditions: the outcome says
        why the run ended, and everything paid for is kept in the run folder.
        """
        reason, message = "completed", "All generations done."
        try:
            while not self.done:
                self.step(progress)
        except BudgetExhausted as exc:
            reason, message = "budget", str(exc)
        except JudgeError as exc:
            reason, message = "judge", str(exc)
        except KeyboardInterrupt:
            reason, message = "interrupted", "Interrupted by the user."
        except SessionError as exc:  # the run folder cannot be written (full disk, ...)
            reason, message = "storage", str(exc)
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
        if progress:
            progress(self._event("end", message=message))
        return RunOutcome(
            reason=reason,
            message=message,
            generations_done=self.generation,
            cost=self.cost,
            run_dir=self.run_dir.root if self.run_dir else None,
            best=self.best(self.settings.top_k),
        )

    # -- outputs --------------------------------------------------------------------------
    def write_outputs(self) -> None:
        """Best renderings, TF JSON, plots, exports, evolution plot and the HTML report."""
        from intuitf.session.outputs import write_run_outputs

        if self.run_dir is not None:
            write_run_outputs(self)

    # -- internals ------------------------------------------------------------------------
    def _event(self, kind: str, **kw) -> ProgressEvent:
        spg = float(np.mean(self.generation_seconds)) if self.generation_seconds else None
        base = dict(
            kind=kind,
            generation=self.generation,
            generations=self.total_generations,
            stage=self.stage,
            cost=self.cost,
            seconds_per_generation=spg,
        )
        base.update(kw)
        return ProgressEvent(**base)

    def _run_async(self, coro):
        if self._loop is None or self._loop.is_closed():
            self._loop = asyncio.new_event_loop()
        try:
            return self._loop.run_until_complete(coro)
        except BaseException:
            # Ctrl-C (or any abort) leaves the round's other requests pending: cancel them
            # and let them unwind, so nothing is left half-started (unanswered requests
            # were not paid for; answered ones are already in the verdict cache).
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

    def close(self) -> None:
        """Release the session's event loop and the judge's connections."""
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

    def _journal(self, entry: dict) -> None:
        if self.run_dir is not None:
            self.run_dir.append_journal(entry)

    def _checkpoint(self) -> None:
        if self.run_dir is None:
            return
        self.run_dir.write_checkpoint(
            {
                "generation": self.generation,
                "stage_index": self.stage_index,
                "explorer": self.explorer.state_dict(),
                "cost": self.cost.to_dict(),
                "ratings": self.ratings,
                "ranking": self.last_ranking,
                "tfs": {k: v.to_dict() for k, v in self.tfs.items()},
                "stage_games": [list(g) for g in self.stage_games],
            }
        )

    def _write_generation_sheet(self, g: int, candidates, ranking: list[str]) -> None:
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


def _save_intent_images(rd: RunDirectory, intent: Intent) -> None:
    from intuitf.imageio import png_bytes
    from intuitf.session.rundir import atomic_write_bytes

    for name in ("reference", "sketch", "base"):
        arr = getattr(intent, name)
        if arr is not None:
            atomic_write_bytes(rd.root / "intent" / f"{name}.png", png_bytes(arr))


def _load_intent(rd: RunDirectory, rec: dict) -> Intent:
    from intuitf.imageio import load_image, load_image_rgba

    imgs = {}
    for name in ("reference", "sketch", "base"):
        p = rd.root / "intent" / f"{name}.png"
        if rec.get(f"has_{name}") and p.exists():
            imgs[name] = load_image_rgba(p) if name == "sketch" else load_image(p)
    return Intent(
        kind=rec.get("kind", "none"),
        text=rec.get("text"),
        about=rec.get("about"),
        selected=tuple(rec.get("selected", ())),
        **imgs,
    )


def _match_dict(m) -> dict:
    if hasattr(m, "to_dict"):
        return m.to_dict()
    return dict(m.__dict__)


def _safe_dict(result) -> dict:
    try:
        return result.to_dict()
    except Exception:  # a partial result must never break saving the rest
        return {}
