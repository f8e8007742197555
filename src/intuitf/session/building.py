"""Building a run's parts from its spec: the judging camera, the judge with its verdict store
and budget, the intent with its pictures, and the spec of a run folder written before specs
existed.

The judging camera of a new run whose spec names none is decided here, once for every front
end (CLI, web, batch, agents, Python API): :func:`judging_camera` applies the sketch rule (a
sketch over a base picture is judged from the camera that picture was rendered with) and
otherwise :func:`default_camera`. The camera chosen is written into the run's settings, so a
resumed run keeps it whatever the default becomes.

Every front end gets these from :meth:`Session.open` / :meth:`Session.resume`; none builds a
judge or reopens a volume itself.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

from intuitf.errors import IntuitfError, SessionError
from intuitf.evaluator.types import Intent
from intuitf.render.camera import DEFAULT_AZIMUTH, DEFAULT_ELEVATION
from intuitf.session.rundir import RunDirectory
from intuitf.session.spec import IntentSpec, JudgeSpec, RunSpec, parse_spec

INTENT_PICTURES = ("reference", "sketch", "base")


def default_camera(volume: Any = None, spec: RunSpec | None = None) -> dict:
    """The camera (``Camera.to_dict()``) a new run judges from when nothing chooses one.

    The one place that decides it for every front end. With a ``volume``, the view is chosen
    for it (:func:`intuitf.intent.viewpoint.choose_view`: upright, the classic three-quarter
    view unless another shows its structures clearly better); without one, the classic view.
    """
    from intuitf.render import Camera

    if volume is not None and getattr(volume, "data", None) is not None:
        # A view that shows the object: upright along the axis it stands on, chosen by
        # viewpoint entropy of its structures (intuitf.intent.viewpoint).
        from intuitf.intent.viewpoint import choose_view
        from intuitf.session.structure_cache import cached_structure_map

        return choose_view(cached_structure_map(volume)).camera.to_dict()
    return Camera(azimuth=DEFAULT_AZIMUTH, elevation=DEFAULT_ELEVATION).to_dict()


def picture_camera(path: str | Path) -> dict | None:
    """The camera a picture intuitf wrote was rendered with (None when it carries no record)."""
    from intuitf.imageio import read_render_metadata
    from intuitf.render import Camera

    record = read_render_metadata(Path(path))
    if not record or not isinstance(record.get("camera"), dict):
        return None
    return Camera.from_dict(record["camera"]).to_dict()


def judging_camera(spec: RunSpec, volume: Any = None, root: Path | None = None) -> dict:
    """The camera a new run of ``spec`` judges from: the spec's own; else, for a sketch drawn
    on a base picture that records its camera, that camera (the strokes mean something only
    where they were drawn); else :func:`default_camera`. ``root`` resolves relative paths."""
    if spec.settings.get("camera"):
        return dict(spec.settings["camera"])
    base = spec.intent.base if spec.intent.kind == "sketch" else None
    if base:
        p = Path(base)
        if root is not None and not p.is_absolute():
            p = root / p
        cam = picture_camera(p) if p.is_file() else None
        if cam is not None:
            return cam
    return default_camera(volume, spec)


def build_judge(spec: JudgeSpec, run_dir: Path | None, protocol: str = "efficient") -> Any:
    """The judge ``spec`` names, with its verdict store in ``run_dir`` and its budget.

    The efficient tournament shows each pair in a seeded random order and re-asks only
    surprising verdicts in the other order, so a model judge asks once per match; the paper's
    protocol asks every pair in both orders. A model judge keeps every answer in
    ``run_dir/verdicts.sqlite``; a resumed run's budget starts from what that store says was
    already paid.
    """
    from intuitf.evaluator.factory import make_judge

    if not spec.is_model:
        return make_judge("metric")
    from intuitf.evaluator.budget import Budget
    from intuitf.evaluator.cache import VerdictCache

    options: dict[str, Any] = {"swap": "never" if protocol == "efficient" else "always"}
    options.update(spec.options)
    if spec.base_url:
        options["base_url"] = spec.base_url
    cache = VerdictCache(RunDirectory(run_dir).verdicts) if run_dir is not None else None
    budget = None
    if spec.budget_usd is not None or spec.budget_calls is not None:
        budget = Budget(max_usd=spec.budget_usd, max_calls=spec.budget_calls)
        if cache is not None:
            # The budget covers the whole run: what the store says was paid, including the
            # requests a killed process had under way.
            budget.restore(cache.spent(), *cache.unsettled())
    try:
        judge = make_judge(spec.spec, cache=cache, budget=budget, **options)
    except BaseException:
        if cache is not None:
            cache.close()
        raise
    if hasattr(judge, "on_adapt") and judge.on_adapt is None:
        from intuitf.evaluator.factory import adaptation_recorder

        # What the judge changes because its server said so goes into run.json.
        judge.on_adapt = adaptation_recorder(run_dir)
    return judge


def resumed_judge_spec(
    spec: JudgeSpec, evaluator: str | None, base_url: str | None
) -> tuple[JudgeSpec, bool]:
    """The judge spec a resume uses, and whether the run moves to another model or server.

    A recorded address whose credentials were redacted must be given again (the error says so).
    """
    from intuitf.evaluator.factory import resume_judge_spec

    new, url, moved = resume_judge_spec(
        {"evaluator": spec.spec, "base_url": spec.base_url}, evaluator, base_url
    )
    return spec.model_copy(update={"spec": new, "base_url": url}), moved


def redacted(spec: RunSpec) -> RunSpec:
    """``spec`` as it may be stored or shown: credentials in URLs replaced by ``***``."""
    from intuitf.evaluator.providers import redact_url

    j = spec.judge
    return spec.model_copy(
        update={"judge": j.model_copy(update={"spec": redact_url(j.spec),
                                             "base_url": redact_url(j.base_url)})}
    )  # fmt: skip


def load_intent(spec: IntentSpec, root: Path | None = None) -> Intent:
    """The :class:`Intent` of ``spec``, its pictures read (paths relative to ``root``)."""
    from intuitf.imageio import load_image, load_image_rgba

    pictures: dict[str, Any] = {}
    for name in INTENT_PICTURES:
        path = getattr(spec, name)
        if path:
            p = Path(path)
            if root is not None and not p.is_absolute():
                p = root / p
            pictures[name] = load_image_rgba(p) if name == "sketch" else load_image(p)
    intent = Intent(
        kind=spec.kind,
        text=spec.text,
        about=spec.about,
        selected=tuple(spec.selected),
        **pictures,
    )
    validate = getattr(intent, "validate", None)
    if callable(validate):
        validate()
    return intent


def copy_intent_pictures(spec: RunSpec, root: Path, folder: str = "intent") -> RunSpec:
    """Copy the intent's pictures into ``root/folder``; the returned spec points at the copies."""
    changes: dict[str, str] = {}
    for name in INTENT_PICTURES:
        path = getattr(spec.intent, name)
        if not path:
            continue
        src = Path(path)
        rel = Path(folder) / f"{name}.png"
        dst = root / rel
        if src.resolve() != dst.resolve():
            if not src.is_file():
                raise IntuitfError(f"The {name} picture {src} does not exist.", "Check the path.")
            dst.parent.mkdir(parents=True, exist_ok=True)
            _copy_as_png(src, dst, name)
        changes[name] = rel.as_posix()
    if not changes:
        return spec
    return spec.model_copy(update={"intent": spec.intent.model_copy(update=changes)})


def save_intent_pictures(intent: Intent, root: Path, folder: str = "intent") -> dict[str, str]:
    """Write an in-memory intent's pictures as PNGs under ``root/folder``; their paths."""
    from intuitf.imageio import png_bytes
    from intuitf.session.rundir import atomic_write_bytes

    out = {}
    for name in INTENT_PICTURES:
        arr = getattr(intent, name)
        if arr is not None:
            rel = Path(folder) / f"{name}.png"
            atomic_write_bytes(root / rel, png_bytes(arr))
            out[name] = rel.as_posix()
    return out


def intent_spec_of(intent: Intent, pictures: dict[str, str]) -> IntentSpec:
    """The spec form of an in-memory intent whose pictures were saved at ``pictures``."""
    return IntentSpec.model_construct(
        kind=intent.kind,
        text=intent.text,
        about=intent.about,
        selected=list(intent.selected),
        reference=pictures.get("reference"),
        sketch=pictures.get("sketch"),
        base=pictures.get("base"),
    )


def _copy_as_png(src: Path, dst: Path, what: str) -> None:
    """Copy a picture, re-encoded as PNG (keeps the sketch's transparency)."""
    from intuitf.imageio import load_image, load_image_rgba, png_bytes
    from intuitf.session.rundir import atomic_write_bytes

    if src.suffix.lower() == ".png":
        shutil.copyfile(src, dst)
        return
    arr = load_image_rgba(src) if what == "sketch" else load_image(src)
    atomic_write_bytes(dst, png_bytes(arr))


def spec_of_record(record: dict) -> RunSpec:
    """The spec of a run folder: ``run.json``'s own, or one rebuilt from an older record."""
    if "spec" in record:
        return parse_spec(record["spec"])
    # Written before specs existed: the CLI kept the volume's source and the judge beside.
    intent = record.get("intent", {}) or {}
    pictures = {
        n: f"intent/{n}.png" for n in INTENT_PICTURES if intent.get(f"has_{n}")
    }  # the old layout kept them there
    try:
        return RunSpec.model_validate(
            {
                "volume": {"source": record.get("volume_source", "phantom"),
                           **(record.get("volume_args") or {})},
                "intent": {
                    "kind": intent.get("kind", "none"),
                    "text": intent.get("text"),
                    "about": intent.get("about"),
                    "selected": list(intent.get("selected", [])),
                    **pictures,
                },
                "judge": {"spec": record.get("evaluator", "metric"),
                          "base_url": record.get("base_url")},
                "settings": record.get("settings", {}),
                "initial": record.get("initial", []),
            }
        )  # fmt: skip
    except Exception as exc:
        raise SessionError(
            f"The run's record cannot be read as a run spec: {exc}.",
            "Start a new run; this folder was written by an incompatible intuitf.",
        ) from exc
