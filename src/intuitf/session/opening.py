"""How a Session comes to be: from a spec, from in-memory objects, from a run folder, or as a
branch of another run. Plain functions; :class:`~intuitf.session.session.Session`'s
classmethods (``open``, ``create``, ``refine``, ``resume``, ``branch``) call them with the
class to build (a subclass, such as the web's live session, gets its own kind back).
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import numpy as np

from intuitf.errors import SessionError
from intuitf.evaluator.types import Cost, Intent, Judge
from intuitf.session.events import EventLog
from intuitf.session.helpers import (
    _fit_line,
    _fit_sketch,
    _intent_record,
    _judge_name,
    _paid,
    _palette_hint,
    _read_intent,
    _with_selection,
)
from intuitf.session.recorder import recorder_for
from intuitf.session.rundir import RunDirectory
from intuitf.session.settings import RunSettings
from intuitf.session.spec import IntentSpec, RunSpec, VolumeSpec, parse_spec
from intuitf.tf import GaussianTF
from intuitf.volume import Volume

if TYPE_CHECKING:
    from intuitf.session.lock import RunLock
    from intuitf.session.session import Session

__all__ = [
    "branch_session",
    "create_session",
    "open_session",
    "refine_session",
    "resume_session",
]

S = TypeVar("S", bound="Session")


def open_session(
    cls: type[S],
    spec: RunSpec | dict[str, Any],
    run_dir: str | Path | None,
    *,
    overwrite: bool = False,
    judge: Judge | None = None,
    volume: Volume | None = None,
) -> S:
    """Start the run ``spec`` describes in ``run_dir`` (None: in memory); see
    :meth:`Session.open <intuitf.session.session.Session.open>`."""
    from intuitf.session.building import (
        build_judge,
        copy_intent_pictures,
        judging_camera,
        load_intent,
    )
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
                f"Continue it with --resume {rd.root}, or pick another folder (-o) or --overwrite.",
            )
        # The volume's path as seen from the run folder too: a moved tree still finds it.
        spec = spec.model_copy(update={"volume": spec.volume.anchored(rd.root)})
        created = not rd.root.exists()
        rd.root.mkdir(parents=True, exist_ok=True)
        lock = RunLock(rd.root)
        lock.acquire()
    try:
        vol = volume if volume is not None else spec.volume.load()
        if rd is not None:
            spec = copy_intent_pictures(spec, rd.root)
        if not settings.camera:  # decided once here, and recorded with the run
            settings.camera = judging_camera(spec, vol, rd.root if rd is not None else None)
            spec = spec.model_copy(
                update={"settings": {**spec.settings, "camera": settings.camera}}
            )
        intent = load_intent(spec.intent, rd.root if rd is not None else None)
        initial = [GaussianTF.from_dict(d) for d in spec.initial]
        if judge is None:
            judge = build_judge(spec.judge, rd.root if rd else None, settings.protocol)
        assert judge is not None
        if spec.intent.kind == "edit":
            if len(initial) != 1:
                raise SessionError(
                    "A refinement starts from exactly one transfer function.",
                    "Give the TF to refine as the spec's only 'initial' entry.",
                )
            sess = _refine_from(
                cls, vol, initial[0], intent, judge, settings, rd, spec, overwrite, lock
            )
        else:
            sess = _new(cls, vol, intent, judge, settings, rd, initial, overwrite, spec, lock)
    except BaseException:
        if lock is not None:
            lock.release()
        if created and rd is not None and not rd.exists():
            import shutil

            shutil.rmtree(rd.root, ignore_errors=True)
        raise
    return sess


def create_session(
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
    """A new run from in-memory objects; see :meth:`Session.create
    <intuitf.session.session.Session.create>`."""
    intent = intent or Intent()
    settings = _with_default_camera(settings or RunSettings(), volume, spec)
    settings.validate()
    rd, lock = _locked(run_dir)
    with _released_on_failure(lock):
        return _new(
            cls, volume, intent, judge or _metric_judge(), settings, rd, list(initial), overwrite,
            spec, lock,
        )  # fmt: skip


def _new(
    cls: type[S],
    volume: Volume,
    intent: Intent,
    judge: Judge,
    settings: RunSettings,
    rd: RunDirectory | None,
    initial: list[GaussianTF],
    overwrite: bool,
    spec: RunSpec | None,
    lock: RunLock | None,
) -> S:
    """A session at generation 0: its Explorer made, its run folder (if any) written."""
    from intuitf.explorer import make_explorer

    settings.validate()
    if rd is not None:
        from intuitf.evaluator.budget import reset_spend

        reset_spend(judge, rd.verdicts)  # a new run has paid nothing yet (--overwrite)
    # A model judge names the volume's structures first (once per volume), so the words of
    # the intent that the first generation's hints are made from match them by name.
    naming = _name_structures(volume, judge, settings)
    counts, _ = volume.histogram()
    hints, understood, reading = _read_intent(intent, settings, volume)
    # A sketch's strokes are fitted first: the fitted TF joins the first generation, and the
    # run judges against the strokes from there on (see ``RunSettings.fit_sketch``).
    fitted = _fit_sketch(intent, settings, volume, reading)
    if fitted is not None:
        understood = [*understood, _fit_line(fitted, intent)]
    plan = settings.stage_plan(intent.kind != "none", at_intent=fitted is not None)
    explorer = make_explorer(
        settings.explorer,
        population=settings.population,
        n_gaussians=settings.n_gaussians,
        generations=plan[0][1],
        stage=plan[0][0],
        seed=settings.seed,
        histogram=counts,
        value_range=volume.value_range,
        initial=list(initial) + ([fitted.tf] if fitted is not None else []),
        palette=_palette_hint(intent, settings),
        hints=hints,
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
                "judges": _judge_history(spec, 0),
                "settings": settings.to_dict(),
                "plan": [list(p) for p in plan],
                "initial": [tf.to_dict() for tf in initial],
                "parent": spec.parent.model_dump() if spec.parent else None,
                "versions": _versions(),
                "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                **({"structures": naming.to_dict()} if naming is not None else {}),
                **({"sketch_fit": _fit_record(fitted)} if fitted is not None else {}),
                "understood": understood,
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
        cost=Cost(**naming.cost.to_dict()) if naming is not None else None,
        plan=plan,
    )
    sess.understood = understood
    sess.events.emit("stage_started", stage=plan[0][0], generations=plan[0][1], generation=0)
    return sess


def _fit_record(fit: Any) -> dict:
    """What run.json keeps of a sketch's fit: the TF and the strokes' errors."""
    return {"tf": fit.tf.to_dict(), "before": list(fit.before), "after": list(fit.after),
            "evaluations": fit.evaluations}  # fmt: skip


def refine_session(
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
    """A run of the refine stage; see :meth:`Session.refine
    <intuitf.session.session.Session.refine>`."""
    intent = Intent(
        kind="edit", text=instruction, selected=tuple(int(i) for i in selected), about=about
    )
    rd, lock = _locked(run_dir)
    with _released_on_failure(lock):
        settings = _with_default_camera(settings or RunSettings(), volume, None)
        return _refine_from(
            cls, volume, tf, intent, judge or _metric_judge(), settings, rd, None, overwrite, lock,
        )  # fmt: skip


def _refine_from(
    cls: type[S],
    volume: Volume,
    tf: GaussianTF,
    intent: Intent,
    judge: Judge,
    settings: RunSettings,
    rd: RunDirectory | None,
    spec: RunSpec | None,
    overwrite: bool,
    lock: RunLock | None,
) -> S:
    if not settings.stages or settings.stages[0][0] != "refine":
        settings.stages = [("refine", settings.generations)]
    intent = _with_selection(intent, volume, [tf], settings)  # base picture and mask
    return _new(cls, volume, intent, judge, settings, rd, [tf], overwrite, spec, lock)


def resume_session(
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
    """Continue the run in ``run_dir`` from its last checkpoint; see :meth:`Session.resume
    <intuitf.session.session.Session.resume>`."""
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
        vol = volume if volume is not None else spec.volume.load(rd.root)
        if (record.get("structures") or {}).get("names"):
            from intuitf.session.structure_cache import cached_structure_map

            # The names a model gave at the opening (kept in the volume's cache): a new
            # question asked during the resumed run matches its words by them too.
            cached_structure_map(vol)
        if judge is None:
            judge = build_judge(spec.judge, rd.root, settings.protocol)
        assert judge is not None
        generation = int(ckpt["generation"]) if ckpt else 0
        stored = redacted(spec).to_dict()
        if moved or stored != record.get("spec"):
            record["spec"] = stored
            judges = record.setdefault("judges", [])
            if moved:
                judges.extend(_judge_history(spec, generation))
                record["judge"] = _judge_name(judge)
            rd.write_run(record)
        if ckpt and ckpt.get("intent"):
            intent = load_intent(_intent_spec(ckpt["intent"]), rd.root)
        else:
            intent = load_intent(spec.intent, rd.root)
        initial_tfs = [GaussianTF.from_dict(d) for d in spec.initial]
        intent = _with_selection(intent, vol, initial_tfs, settings)
        if ckpt is None:
            # Stopped before the first generation finished: start over, same seed; the
            # verdict store still holds whatever was paid for.
            sess = _new(cls, vol, intent, judge, settings, None, initial_tfs, False, spec, lock)
            sess.run_dir = rd
            sess.recorder = recorder_for(rd)
            sess.name = rd.root.name
            sess.events = EventLog(sess.name, sess.recorder.events_path)
            sess.cost = _paid(judge, sess.cost, rd)
        else:
            sess = _from_checkpoint(cls, vol, intent, judge, settings, rd, ckpt, spec, lock)
        sess.judge_moved = moved
        # How the words now asked were read: a later query's lines (in the checkpoint), else
        # the opening's.
        said = (ckpt or {}).get("understood")
        sess.understood = [
            str(x) for x in (said if said is not None else record.get("understood") or [])
        ]
        if moved:
            sess.recorder.journal(
                {"type": "judge", "generation": generation, "judge": _judge_name(judge)}
            )
        sess._refresh()
        return sess
    except BaseException:
        lock.release()
        raise


def _from_checkpoint(
    cls: type[S],
    vol: Volume,
    intent: Intent,
    judge: Judge,
    settings: RunSettings,
    rd: RunDirectory,
    ckpt: dict[str, Any],
    spec: RunSpec,
    lock: RunLock,
) -> S:
    """The session a checkpoint describes (the state after its last finished generation)."""
    from intuitf.explorer import explorer_from_state

    sess = cls(
        vol,
        intent=intent,
        judge=judge,
        settings=settings,
        run_dir=rd,
        explorer=explorer_from_state(ckpt["explorer"]),
        stage_index=int(ckpt["stage_index"]),
        generation=int(ckpt["generation"]),
        cost=_paid(judge, Cost(**ckpt.get("cost", {})), rd),
        ratings={k: float(v) for k, v in ckpt.get("ratings", {}).items()},
        last_ranking=list(ckpt.get("ranking", [])),
        population_tfs={k: GaussianTF.from_dict(v) for k, v in ckpt.get("tfs", {}).items()},
        stage_games=ckpt.get("stage_games", []),
        plan=ckpt.get("plan"),
        spec=spec,
        queries=int(ckpt.get("queries", 0)),
        lock=lock,
    )
    sess._restore(ckpt)  # the verdict loop, the current intent, what was paid by then
    return sess


def branch_session(
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
    """A new run from another's generation or candidate; see :meth:`Session.branch
    <intuitf.session.session.Session.branch>`."""
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
    link: dict[str, Any] = {"run": str(parent.root), "generation": generation,
                            "candidate": candidate}  # fmt: skip
    if candidate is not None:
        tf = _candidate_tf(parent, candidate)
        base["initial"] = [tf.to_dict()]
        if (base.get("intent") or {}).get("kind") == "edit":
            link["selected"] = list(base["intent"].get("selected", []))
    base["parent"] = link
    spec = parse_spec(base)
    if generation is None or generation == 0 or candidate is not None:
        return open_session(cls, spec, run_dir, judge=judge, volume=volume)
    ckpt_path = parent.generation_checkpoint(generation)
    if not ckpt_path.exists():
        raise SessionError(
            f"{parent.root} has no saved state for generation {generation}.",
            "Branch from a generation the run has finished (see its history).",
        )
    ParentLink.model_validate(link)
    sess = open_session(cls, spec, run_dir, judge=judge, volume=volume)
    # Take over the parent's state at that generation, then continue as a resume would.
    import json

    state = json.loads(ckpt_path.read_text(encoding="utf-8"))
    state["cost"] = Cost().to_dict()  # the branch pays only for what it asks itself
    assert sess.run_dir is not None
    sess.run_dir.write_checkpoint(state)
    rd_root, judge_used, vol = sess.run_dir.root, sess.judge, sess.volume
    sess.close()
    return resume_session(cls, rd_root, vol, judge_used)


# -- helpers -----------------------------------------------------------------------------
def _versions() -> dict[str, str]:
    import platform

    import numba

    import intuitf

    return {
        "intuitf": intuitf.__version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
    }


def _intent_spec(rec: dict[str, Any]) -> IntentSpec:
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


def _spec_for_record(
    spec: RunSpec | None,
    intent: Intent,
    settings: RunSettings,
    initial: list[GaussianTF],
    judge: Judge,
    rd: RunDirectory,
) -> RunSpec:
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


def _volume_spec_unknown() -> VolumeSpec:
    # An in-memory volume has no source to reopen; resuming needs the volume passed in.
    return VolumeSpec.model_construct(source="", shape=None, dtype=None, byte_order=None,
                                      spacing=None, max_dim=None)  # fmt: skip


def _moved_spec(
    spec: RunSpec,
    evaluator: str | None,
    base_url: str | None,
    budget_usd: float | None,
    budget_calls: int | None,
    options: dict[str, Any] | None,
    build: bool,
) -> tuple[RunSpec, bool]:
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


def _judge_history(spec: RunSpec, generation: int) -> list[dict[str, Any]]:
    """run.json's record of a judge taking over at ``generation`` (credentials redacted)."""
    from intuitf.evaluator.factory import judge_record

    return judge_record(spec.judge.spec, spec.judge.base_url, generation)["judges"]


@contextmanager
def _released_on_failure(lock: RunLock | None) -> Iterator[None]:
    """Release ``lock`` when the block raises (the run was not opened), then re-raise."""
    try:
        yield
    except BaseException:
        if lock is not None:
            lock.release()
        raise


def _locked(run_dir: str | Path | None) -> tuple[RunDirectory | None, RunLock | None]:
    """The run folder (made if missing) and this process's lock on it; (None, None) in memory."""
    from intuitf.session.lock import RunLock

    if run_dir is None:
        return None, None
    rd = RunDirectory(run_dir)
    rd.root.mkdir(parents=True, exist_ok=True)
    return rd, RunLock(rd.root).acquire()


def _with_default_camera(
    settings: RunSettings, volume: Volume, spec: RunSpec | None
) -> RunSettings:
    """``settings`` with the default judging camera filled in when they name none (a copy:
    the caller's object is left as it was)."""
    if settings.camera:
        return settings
    from dataclasses import replace

    from intuitf.session.building import default_camera

    return replace(settings, camera=default_camera(volume, spec))


def _name_structures(volume: Volume, judge: Judge, settings: RunSettings) -> Any:
    """The structures named by a model judge (:mod:`intuitf.session.naming`; None for other
    judges), seen from the run's judging camera."""
    from intuitf.session.naming import asks_names, name_run_structures

    if not settings.name_structures or not asks_names(judge):
        return None
    from intuitf.render import Camera

    camera = Camera.from_dict(settings.camera) if settings.camera else None
    return name_run_structures(volume, judge, camera)


def _metric_judge() -> Judge:
    from intuitf.evaluator.metric import MetricJudge

    return MetricJudge()
