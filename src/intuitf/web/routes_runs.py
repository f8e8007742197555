"""Runs: start, list, the history tree, one run's state and gallery, control (pause, proceed,
cancel, continue), a new query, refinement and branches, a person's verdicts, the matches
the judge decided, generation thumbnails and the event stream."""

from __future__ import annotations

import asyncio
from typing import Any, Literal

from fastapi import APIRouter, Header, Query, Request
from fastapi.responses import FileResponse, Response, StreamingResponse
from pydantic import BaseModel, ConfigDict, Field

from intuitf.errors import IntuitfError, RunLocked
from intuitf.session.live import LiveSession, NotLive
from intuitf.session.scheduler import INTERACTIVE, render_scheduler
from intuitf.web.common import (
    ApiError,
    background_of,
    camera_of,
    check_candidate_id,
    check_run_name,
    state,
    user_error,
)
from intuitf.web.schema import COMMON

router = APIRouter(prefix="/api", tags=["runs"], responses=COMMON)


# -- request bodies ----------------------------------------------------------------------------
class _In(BaseModel):
    model_config = ConfigDict(extra="forbid")


class IntentIn(_In):
    kind: Literal["none", "text", "image", "sketch", "edit"] = "none"
    text: str | None = None
    about: str | None = None
    reference: str | None = Field(None, description='"upload:ID"')
    sketch: str | None = Field(None, description='"upload:ID" (RGBA strokes)')
    base: str | None = Field(None, description='"upload:ID" or "candidate:RUN/gGGG-NNN"')
    selected: list[int] = Field(default_factory=list)


class JudgeIn(_In):
    spec: str = "metric"
    base_url: str | None = None
    budget_usd: float | None = Field(None, ge=0)
    budget_calls: int | None = Field(None, ge=0)
    options: dict[str, Any] = Field(default_factory=dict)


class RunIn(_In):
    version: int | None = None
    name: str | None = Field(None, max_length=100)
    volume: str = Field(..., description="a volume id from GET /api/volumes")
    intent: IntentIn | str | None = None
    judge: JudgeIn | str | None = None
    settings: dict[str, Any] = Field(default_factory=dict)
    initial: list[dict[str, Any]] = Field(default_factory=list)


class NameOut(BaseModel):
    name: str


class ContinueIn(_In):
    budget_usd: float | None = Field(None, ge=0)
    budget_calls: int | None = Field(None, ge=0)
    evaluator: str | None = None
    base_url: str | None = None


class QueryIn(_In):
    intent: IntentIn
    generations: int | None = Field(None, ge=1, le=1000)


class RefineIn(_In):
    candidate: str
    selected: list[int] = Field(..., min_length=1)
    text: str = Field(..., min_length=1)
    generations: int | None = Field(None, ge=1, le=1000)


class BranchIn(_In):
    generation: int | None = Field(None, ge=0)
    candidate: str | None = None
    changes: dict[str, Any] | None = None


class PreferIn(_In):
    better: str
    worse: str


class BestIn(_In):
    best: str
    among: list[str] = Field(..., min_length=2)


class WorstIn(_In):
    worst: str
    among: list[str] = Field(..., min_length=2)


class UndoIn(_In):
    id: int | None = None


class RenameIn(_In):
    title: str = Field(..., min_length=1, max_length=100, description="the run's shown name")


class StatusOut(BaseModel):
    name: str
    status: str


class VerdictOut(BaseModel):
    verdict: dict[str, Any]
    ranking: list[str]


class QueryOut(BaseModel):
    name: str
    status: str
    applied: bool


# -- helpers -----------------------------------------------------------------------------------
def _run_dir(web, name: str):
    check_run_name(name)
    web.record(name)  # 404 unless it is a run
    return web.store.path_of(name)


def _live_or_409(web, name: str):
    live = web.registry.get(name)
    if live is None:
        web.record(name)
        raise ApiError(409, f"The run {name!r} is not going.", "Continue it first.")
    return live


def _render_candidate_base(web, qid: str, camera, size: int, shading: bool, background):
    """The rendering of a candidate to draw a sketch on (blocking; on the render worker)."""
    from intuitf.imageio import png_bytes

    info = web.candidate(qid)
    volume = web.volume_of_run(info.run)
    vr = web.view_renderer(volume, background)
    image = render_scheduler().call(lambda: vr.view(info.tf, camera, size, shading), INTERACTIVE)
    pid = web.pictures.save(png_bytes(image))["id"]
    return str(web.pictures.path(pid))


def resolve_intent(web, intent: IntentIn | str | None, camera, size: int, shading, background):
    """Spec data of an intent whose pictures are upload ids (blocking: may render a base)."""
    if intent is None:
        return {}
    if isinstance(intent, str):
        return {"kind": "text", "text": intent}
    data = intent.model_dump()
    sketch_size = None
    if intent.sketch:
        sketch_size = _picture_path_size(web, intent.sketch, "sketch")
    for field in ("reference", "sketch", "base"):
        value = data.get(field)
        if not value:
            continue
        kind, _, ref = value.partition(":")
        if kind == "upload" and ref:
            data[field] = str(web.pictures.path(ref))
        elif kind == "candidate" and field == "base" and ref:
            w = sketch_size[0] if sketch_size else size
            data[field] = _render_candidate_base(web, ref, camera, w, shading, background)
        else:
            raise ApiError(
                422,
                f'The {field} picture must be an upload id ("upload:ID"), got {value[:60]!r}.',
                "Upload the picture with POST /api/uploads and use the id it returns.",
            )
    return data


def _picture_path_size(web, value: str, field: str):
    kind, _, ref = value.partition(":")
    if kind != "upload" or not ref:
        raise ApiError(422, f'The {field} picture must be an upload id ("upload:ID").')
    return web.pictures.size(ref)


class FieldsError(ApiError):
    """A 422 that names each bad field (``errors: [{loc, msg}]``, as request validation)."""

    def __init__(self, detail: str, hint: str | None, fields: dict[str, str]) -> None:
        super().__init__(422, detail, hint)
        self.fields = fields

    def body(self) -> dict[str, Any]:
        out = super().body()
        out["errors"] = [{"loc": path.split("."), "msg": msg} for path, msg in self.fields.items()]
        return out


def spec_error(exc: IntuitfError) -> ApiError:
    """A refused run spec as a 422 naming its fields where the spec's validation did."""
    fields = getattr(exc, "fields", None)
    if isinstance(fields, dict) and fields:
        return FieldsError(exc.message, exc.hint, {str(k): str(v) for k, v in fields.items()})
    return user_error(exc)


#: The stages a run's plan may name.
STAGES = ("initialize", "customize", "refine")


def check_settings(settings: dict[str, Any]):
    """:class:`RunSettings` from a request's settings, or a 422 naming what is wrong. Checked
    here, before anything is written: values of the wrong type, out of range, unknown stages,
    a background or camera no view can show."""
    from intuitf.session.settings import RunSettings

    def bad(field: str, msg: str) -> FieldsError:
        return FieldsError(
            f"The settings are not valid: {field}: {msg}.",
            "Fix the field named above.",
            {f"settings.{field}": msg},
        )

    unknown = sorted(set(settings) - RunSettings.field_names())
    if unknown:
        raise bad(
            unknown[0], f"unknown setting (known: {', '.join(sorted(RunSettings.field_names()))})"
        )
    for key in ("population", "generations", "n_gaussians", "seed", "image_size", "output_size",
                "top_k"):  # fmt: skip
        v = settings.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int)):
            raise bad(key, f"must be a whole number, got {v!r}"[:120])
    seed = settings.get("seed")
    if seed is not None and not 0 <= seed < 2**32:
        raise bad("seed", f"must be within 0..{2**32 - 1}, got {seed}")
    stages = settings.get("stages")
    if stages is not None:
        if not isinstance(stages, list):
            raise bad("stages", "must be a list of [stage, generations] pairs")
        for item in stages:
            ok = isinstance(item, list | tuple) and len(item) == 2
            if not ok or item[0] not in STAGES:
                raise bad("stages", f"each is [stage, generations] with a stage of {STAGES}")
            n = item[1]
            if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 10_000:
                raise bad("stages", f"{item[0]}: generations must be within 1..10000")
    try:
        rs = RunSettings.from_dict(settings)
        rs.validate()
    except IntuitfError as exc:
        raise ApiError(422, f"The settings are not valid: {exc.message}", exc.hint) from None
    except (TypeError, ValueError) as exc:
        raise ApiError(422, f"The settings are not valid: {exc}.", "Check their types.") from None
    try:
        background_of(rs.background)
    except ApiError as exc:
        raise bad("background", exc.detail) from None
    return rs


def _build_spec(web, body: RunIn):
    from intuitf.session.spec import parse_spec

    entry = web.catalog.get(body.volume)
    settings = {**web.default_settings, **body.settings}
    rs = check_settings(settings)
    camera = camera_of(rs.camera or None)
    size, shading, bg = rs.image_size, rs.shading, tuple(rs.background)
    intent = resolve_intent(web, body.intent, camera, size, shading, bg)
    judge: Any = body.judge if body.judge is not None else web.evaluator
    if isinstance(judge, JudgeIn):
        judge = judge.model_dump()
    elif isinstance(judge, str) and getattr(web, "judge_options", None):
        judge = {"spec": judge, "options": dict(web.judge_options)}  # serve's judge options
    data = {
        "volume": entry.spec().model_dump(exclude_none=True),
        "intent": intent,
        "judge": judge,
        "settings": settings,
        "initial": body.initial,
    }
    try:
        return entry, parse_spec(data)
    except IntuitfError as exc:
        raise spec_error(exc) from None
    except (TypeError, ValueError) as exc:
        raise ApiError(422, f"The run spec is not valid: {exc}.", "Check the fields.") from None


async def _reopen(web, name: str, *, for_verdict: bool = False, **kw) -> LiveSession:
    """Open a run that is not live with :meth:`Session.resume` (in a worker thread)."""
    await web.registry.wait_released(name)
    run_dir = _run_dir(web, name)
    record = await asyncio.to_thread(web.record, name)
    if record.get("kind") == "edit":
        raise ApiError(
            409,
            f"{name!r} is a hand edit, not a run.",
            "Branch or refine from its candidate instead.",
        )
    volume = await asyncio.to_thread(web.volume_of_run, name)
    judge = None
    if for_verdict:  # a verdict asks no model: no key or server needed to record it
        from intuitf.evaluator.metric import MetricJudge

        judge = MetricJudge()
    try:
        return await asyncio.to_thread(LiveSession.resume, run_dir, volume, judge, **kw)
    except RunLocked as exc:  # another process drives its folder
        raise ApiError(409, exc.message, exc.hint) from None
    except IntuitfError as exc:
        raise ApiError(422, exc.message, exc.hint) from None


async def _start(web, session: LiveSession) -> str:
    try:
        web.registry.check_capacity()
        web.registry.start(session)
    except BaseException:
        await session.aclose()
        raise
    return session.name


#: Largest difference of two TFs' RGBA lookup tables (any entry, any channel) below which the
#: gallery folds them: a refinement that changes one feature a little still shows apart.
SIMILAR_LUT = 0.02
GALLERY = 8


def fold_gallery(name: str, ranking, tfs, ratings, k: int = GALLERY) -> list[dict]:
    """The top ``k`` results of a ranking, each near-duplicate (a TF whose lookup table is
    almost the same as a better one's) folded into the better one's ``similar`` list."""
    import numpy as np

    from intuitf.tf import GaussianTF

    out: list[dict] = []
    luts: list[np.ndarray] = []
    for rank, cid in enumerate(ranking, start=1):
        tf = tfs.get(cid)
        if tf is None:
            continue
        try:
            tf = tf if isinstance(tf, GaussianTF) else GaussianTF.from_dict(tf)
            lut = tf.lut(128)
        except (IntuitfError, TypeError, ValueError, KeyError):
            continue
        twin = next((i for i, other in enumerate(luts)
                     if float(np.abs(lut - other).max()) < SIMILAR_LUT), None)  # fmt: skip
        if twin is not None:
            out[twin]["similar"].append(cid)
            continue
        if len(out) >= k:
            continue  # only folds into the shown ones from here on
        luts.append(lut)
        rating = ratings.get(cid)
        if rating is not None and not np.isfinite(float(rating)):
            rating = None
        out.append({"id": cid, "qid": f"{name}/{cid}", "rank": rank, "similar": [],
                    "rating": None if rating is None else float(rating)})  # fmt: skip
        if len(out) >= k and rank > 4 * k:
            break
    return out


def _gallery_from_checkpoint(web, name: str) -> list[dict]:
    from intuitf.session import RunDirectory

    rd = RunDirectory(web.store.path_of(name))
    try:
        ckpt = rd.read_checkpoint() or {}
    except IntuitfError:
        ckpt = {}
    ranking, ratings, tfs = ckpt.get("ranking", []), ckpt.get("ratings", {}), ckpt.get("tfs", {})
    if not ranking:  # no checkpoint (a hand edit, an old run): the journal's last generation
        gens = rd.generations()
        cands = (
            sorted(gens[-1].get("candidates", []), key=lambda c: c.get("rank", 0)) if gens else []
        )
        ranking = [c["id"] for c in cands]
        ratings = {c["id"]: c.get("rating") for c in cands}
        tfs = {c["id"]: c.get("tf") for c in cands}
    return fold_gallery(name, ranking, tfs, ratings)


def _thumbnail_url(name: str, g: int) -> str:
    return f"/api/runs/{name}/generations/{g}/thumbnail"


INTERRUPTED = (
    "The server stopped while this run was going (a crash or a kill); "
    "Resume goes on from its last finished generation."
)


#: The page's own notes on a run (its shown title), beside the run's files.
WEB_NOTES = "web.json"
#: Where deleted runs are moved (hidden: the run list shows only folders with a run.json).
TRASH = ".deleted"


def _title(web, name: str) -> str | None:
    import json

    try:
        notes = json.loads((web.store.path_of(name) / WEB_NOTES).read_text(encoding="utf-8"))
        title = notes.get("title")
        return str(title) if title else None
    except (OSError, ValueError, IntuitfError, AttributeError):
        return None


def status_now(web, info: dict[str, Any]) -> dict[str, Any]:
    info = {**info, "title": _title(web, info["name"])}
    return _status_now(web, info)


def _status_now(web, info: dict[str, Any]) -> dict[str, Any]:
    """A run's listing as a person should read it now.

    A run that has ended but still writes its best pictures and exports holds its folder's
    lock, so the store says "running": its outcome is what counts. A run that neither ended
    (no end in its journal) nor is held by any process was cut off by a crash: "interrupted".
    """
    status = info.get("status")
    entry = web.registry.entry(info["name"])
    if status == "running" and entry is not None and not entry.live:
        outcome = entry.outcome
        if outcome is not None:
            message = getattr(outcome, "message", None) or info.get("message", "")
            return {**info, "status": outcome.reason, "message": message}
        status = "stopped"  # it failed: its run_ended event says how
    if status in ("stopped", "new"):
        last = _last_run_event(web, info["name"])
        if last is not None and last.get("type") == "run_ended":  # ended without a journal end
            data = last.get("data") or {}
            return {**info, "status": str(data.get("reason") or status),
                    "message": str(data.get("message") or info.get("message", ""))}  # fmt: skip
        if last is not None or status == "stopped":
            return {**info, "status": "interrupted", "message": INTERRUPTED}
    return info


def _last_run_event(web, name: str) -> dict | None:
    """The run's last run_started or run_ended event (None if it never started)."""
    import json

    from intuitf.session import RunDirectory

    try:
        path = RunDirectory(web.store.path_of(name)).events
        with open(path, "rb") as f:
            lines = f.read().splitlines()
    except (OSError, IntuitfError):
        return None
    for line in reversed(lines):
        if b'"run_started"' in line or b'"run_ended"' in line:
            try:
                return json.loads(line)
            except ValueError:
                return None
    return None


# -- runs ----------------------------------------------------------------------------------------
@router.get("/runs")
def list_runs(request: Request) -> list[dict[str, Any]]:
    web = state(request)
    return [status_now(web, r.to_dict()) for r in web.store.runs()]


@router.post("/runs", response_model=NameOut, status_code=201)
async def start_run(request: Request, body: RunIn) -> dict:
    web = state(request)
    web.registry.check_capacity()
    entry, spec = await asyncio.to_thread(_build_spec, web, body)
    async with web.create_lock:
        run_dir = web.store.new_run_dir(body.name or entry.id)  # the session's naming rule
        name = run_dir.name
        volume = await asyncio.to_thread(web.catalog.load, entry.id)
        spec = spec.model_copy(update={"name": name})
        try:
            session = await asyncio.to_thread(LiveSession.open, spec, run_dir, volume=volume)
        except IntuitfError as exc:
            await asyncio.to_thread(_discard, run_dir)
            raise spec_error(exc) from None
        except (TypeError, ValueError) as exc:
            await asyncio.to_thread(_discard, run_dir)
            raise ApiError(422, f"The run cannot start: {exc}.", "Check the settings.") from None
    return {"name": await _start(web, session)}


def _discard(run_dir) -> None:
    """Remove the folder of a run refused while it was being opened (nothing of it is kept:
    it never ran), so that it shows nowhere."""
    import shutil

    if run_dir.is_dir():
        shutil.rmtree(run_dir, ignore_errors=True)


@router.post("/runs/{name}/rename", response_model=NameOut)
def rename_run(request: Request, name: str, body: RenameIn) -> dict:
    """Give a run the title the page shows (its folder and id stay, so branches and
    addresses that name it keep working)."""
    import json

    web = state(request)
    run_dir = _run_dir(web, name)
    title = " ".join(body.title.split())
    if not title:
        raise ApiError(422, "A title needs some text.")
    (run_dir / WEB_NOTES).write_text(json.dumps({"title": title}), encoding="utf-8")
    return {"name": name}


@router.delete("/runs/{name}", status_code=204, response_class=Response)
async def delete_run(request: Request, name: str) -> Response:
    """Delete a run that is not going and has no branches: its folder is moved aside (into
    the runs folder's hidden .deleted/), so nothing shows it and nothing is lost by a slip."""
    import shutil
    import time

    web = state(request)
    run_dir = _run_dir(web, name)
    if web.registry.entry(name) is not None:
        raise ApiError(409, f"The run {name!r} is going.", "Stop it first.")
    await web.registry.wait_released(name)
    info = await asyncio.to_thread(web.store.run, name)
    if info.status == "running":
        raise ApiError(409, f"The run {name!r} is in use by another process.")
    children = [r.name for r in await asyncio.to_thread(web.store.runs)
                if (r.parent or {}).get("run") == name]  # fmt: skip
    if children:
        raise ApiError(
            409,
            f"Runs branch from {name!r} ({', '.join(children[:5])}).",
            "Delete its branches first.",
        )
    trash = web.runs_dir / TRASH
    trash.mkdir(exist_ok=True)
    await asyncio.to_thread(shutil.move, str(run_dir), str(trash / f"{name}-{int(time.time())}"))
    web.candidates.clear()
    return Response(status_code=204)


@router.get("/tree")
def tree(request: Request) -> list[dict[str, Any]]:
    web = state(request)
    nodes = web.store.tree()

    def fix(node: dict) -> None:
        node["run"] = status_now(web, node["run"])
        name = node["run"]["name"]
        for g in node["generations"]:
            g["thumbnail"] = _thumbnail_url(name, g["generation"]) if g.get("thumbnail") else None
        for child in node["children"]:
            fix(child)

    for n in nodes:
        fix(n)
    return nodes


@router.get("/runs/{name}")
async def run_detail(request: Request, name: str) -> dict[str, Any]:
    web = state(request)
    check_run_name(name)
    try:
        info = await asyncio.to_thread(web.store.run, name)
    except IntuitfError:
        raise ApiError(404, f"There is no run {name!r}.", "Use a name from the run list.") from None
    where = await asyncio.to_thread(_run_view, web, name)
    info_d = status_now(web, info.to_dict())
    live = web.registry.get(name)
    if live is not None:
        s = live.session
        try:
            ranking, tfs, ratings = await live.call(
                lambda: (list(s.last_ranking), dict(s.tfs), dict(s.ratings))
            )
            snap = s.snapshot()
            gallery = await asyncio.to_thread(fold_gallery, name, ranking, tfs, ratings)
            return {
                **where,
                "info": info_d,
                "snapshot": snap.to_dict(),
                "gallery": gallery,
                "progress": live.progress.to_dict(),
            }
        except NotLive:
            pass
    gallery = await asyncio.to_thread(_gallery_from_checkpoint, web, name)
    cost = info.cost or {}
    return {
        **where,
        "info": info_d,
        "snapshot": None,
        "gallery": gallery,
        "progress": {
            "stage": None,
            "generation": info.generations_done,
            "generations": info.generations,
            "matches_done": 0,
            "matches_total": 0,
            "calls": cost.get("calls", 0),
            "usd": cost.get("usd", 0.0),
            "seconds_left": None,
            "status": info_d["status"],
            "last_error": None,
        },
    }


# -- control -------------------------------------------------------------------------------------
async def _control(request: Request, name: str, action: str) -> dict:
    web = state(request)
    live = _live_or_409(web, name)
    s = live.session
    try:
        await live.call(getattr(s, action))
    except NotLive:
        raise ApiError(409, f"The run {name!r} has ended.", "Continue it to go on.") from None
    return {"name": name, "status": s.snapshot().status if action != "cancel" else "cancelling"}


@router.post("/runs/{name}/pause", response_model=StatusOut)
async def pause(request: Request, name: str) -> dict:
    return await _control(request, name, "pause")


@router.post("/runs/{name}/proceed", response_model=StatusOut)
async def proceed(request: Request, name: str) -> dict:
    return await _control(request, name, "proceed")


@router.post("/runs/{name}/cancel", response_model=StatusOut)
async def cancel(request: Request, name: str) -> dict:
    return await _control(request, name, "cancel")


@router.post("/runs/{name}/continue", response_model=StatusOut)
async def continue_run(request: Request, name: str, body: ContinueIn | None = None) -> dict:
    web = state(request)
    check_run_name(name)
    if web.registry.get(name) is not None:
        raise ApiError(409, f"The run {name!r} is going already.")
    web.registry.check_capacity()
    body = body or ContinueIn()
    session = await _reopen(
        web, name, evaluator=body.evaluator, base_url=body.base_url,
        budget_usd=body.budget_usd, budget_calls=body.budget_calls,
    )  # fmt: skip
    if session.done:
        await session.aclose()
        raise ApiError(
            409,
            f"The run {name!r} has done all its generations.",
            "Ask a new query to go on with it, or branch from it.",
        )
    await _start(web, session)
    return {"name": name, "status": "running"}


@router.post("/runs/{name}/query", response_model=QueryOut, status_code=202)
async def query(request: Request, name: str, body: QueryIn) -> dict:
    from intuitf.render import Camera
    from intuitf.session.building import load_intent
    from intuitf.session.spec import IntentSpec

    web = state(request)
    _run_dir(web, name)
    rs = await asyncio.to_thread(web.run_settings, name)
    camera = Camera.from_dict(rs.camera) if rs.camera else Camera()

    def build():
        data = resolve_intent(web, body.intent, camera, rs.image_size, rs.shading,
                              tuple(rs.background))  # fmt: skip
        try:
            return load_intent(IntentSpec.model_validate(data))
        except IntuitfError as exc:
            raise user_error(exc) from None
        except ValueError as exc:
            raise ApiError(422, f"The intent is not valid: {exc}.") from None

    intent = await asyncio.to_thread(build)
    gens = body.generations
    live = web.registry.get(name)
    if live is not None:
        s = live.session
        try:
            deferred = await live.call(
                lambda: (s.at_boundary(lambda: s.query(intent, gens)), s.has_deferred())[1]
            )
            return {"name": name, "status": "running", "applied": not deferred}
        except NotLive:
            pass
    web.registry.check_capacity()
    session = await _reopen(web, name)
    try:
        await asyncio.to_thread(session.query, intent, gens)
    except BaseException:
        await session.aclose()
        raise
    await _start(web, session)
    return {"name": name, "status": "running", "applied": True}


@router.post("/runs/{name}/refine", response_model=NameOut, status_code=201)
async def refine(request: Request, name: str, body: RefineIn) -> dict:
    web = state(request)
    parent_dir = _run_dir(web, name)
    cid = check_candidate_id(body.candidate)
    info = await asyncio.to_thread(web.candidate, f"{name}/{cid}")
    bad = [i for i in body.selected if not 0 <= i < len(info.tf)]
    if bad:
        raise ApiError(
            422,
            f"The transfer function has {len(info.tf)} Gaussians; {bad} are not among them.",
            "Select Gaussians by their 0-based index.",
        )
    record = await asyncio.to_thread(web.record, name)
    about = ((record.get("spec") or {}).get("intent") or {}).get("about")
    n = body.generations or int((record.get("settings") or {}).get("generations", 4))
    web.registry.check_capacity()
    changes = {
        "intent": {"kind": "edit", "text": body.text, "selected": list(body.selected),
                   "about": about},
        "settings": {"generations": n, "stages": [["refine", n]]},
    }  # fmt: skip
    return {"name": await _branch(web, name, parent_dir, f"{name}-refine", None, cid, changes)}


@router.post("/runs/{name}/branch", response_model=NameOut, status_code=201)
async def branch(request: Request, name: str, body: BranchIn) -> dict:
    web = state(request)
    parent_dir = _run_dir(web, name)
    cid = check_candidate_id(body.candidate) if body.candidate else None
    if cid is not None:
        await asyncio.to_thread(web.candidate, f"{name}/{cid}")
    changes = dict(body.changes or {})
    if "parent" in changes:
        raise ApiError(422, "A branch's parent is the run it branches from; do not set it.")
    if "volume" in changes:
        vid = changes["volume"]
        if not isinstance(vid, str):
            raise ApiError(422, "The volume is named by its id.", "Use an id from /api/volumes.")
        changes["volume"] = web.catalog.get(vid).spec().model_dump(exclude_none=True)
    if "intent" in changes:
        rs = await asyncio.to_thread(web.run_settings, name)
        try:
            intent_in = (
                IntentIn.model_validate(changes["intent"])
                if not isinstance(changes["intent"], str | None)
                else changes["intent"]
            )
        except ValueError as exc:
            raise ApiError(422, f"The intent is not valid: {exc}.") from None
        camera = camera_of(rs.camera or None)
        changes["intent"] = await asyncio.to_thread(
            resolve_intent, web, intent_in, camera, rs.image_size, rs.shading, tuple(rs.background)
        )
    if "settings" in changes:
        if not isinstance(changes["settings"], dict):
            raise ApiError(422, "The settings of a branch are a JSON object.")
        parent_settings = (await asyncio.to_thread(web.record, name)).get("settings") or {}
        check_settings({**parent_settings, **changes["settings"]})
    if cid is not None:
        changes = await asyncio.to_thread(_no_second_initialize, web, name, changes)
    web.registry.check_capacity()
    return {
        "name": await _branch(
            web, name, parent_dir, f"{name}-branch", body.generation, cid, changes
        )
    }


def _no_second_initialize(web, name: str, changes: dict[str, Any]) -> dict[str, Any]:
    """A branch from a candidate of a run that has found its structures (it ran its
    initialize stage) goes straight to its query: no second initialize stage."""
    record = web.record(name)
    settings = {**(record.get("settings") or {}), **(changes.get("settings") or {})}
    if settings.get("stages") and "stages" in (changes.get("settings") or {}):
        return changes  # a plan asked for explicitly
    intent = changes.get("intent", ((record.get("spec") or {}).get("intent") or {}))
    kind = intent.get("kind", "text") if isinstance(intent, dict) else "text"
    if kind in (None, "none", "edit"):
        return changes
    done = [g.get("stage") for g in web.store.history(name)]
    if "initialize" not in done:
        return changes
    n = int(settings.get("generations") or 4)
    return {
        **changes,
        "settings": {**(changes.get("settings") or {}), "stages": [["customize", n]]},
    }


async def _branch(web, name, parent_dir, base_name, generation, cid, changes) -> str:
    from intuitf.session.spec import VolumeSpec

    volume = None
    if "volume" in changes:
        volume = await asyncio.to_thread(web.catalog.load_spec, VolumeSpec(**changes["volume"]))
    else:
        volume = await asyncio.to_thread(web.volume_of_run, name)
    async with web.create_lock:
        new_dir = web.store.new_run_dir(base_name)
        new = new_dir.name
        changes = {**changes, "name": new}
        try:
            session = await asyncio.to_thread(
                LiveSession.branch, parent_dir, new_dir,
                generation=generation, candidate=cid, changes=changes, volume=volume,
            )  # fmt: skip
        except IntuitfError as exc:
            raise user_error(exc) from None
    return await _start(web, session)


# -- a person's verdicts ------------------------------------------------------------------------
async def _human(request: Request, name: str, fn) -> dict:
    web = state(request)
    check_run_name(name)
    live = web.registry.get(name)
    if live is not None:
        s = live.session
        try:
            v, ranking = await live.call(lambda: (fn(s), list(s.last_ranking)))
            return {"verdict": v.to_dict(), "ranking": ranking}
        except NotLive:
            pass
        except IntuitfError as exc:
            raise user_error(exc) from None
    session = await _reopen(web, name, for_verdict=True)
    try:
        v = await asyncio.to_thread(fn, session)
        return {"verdict": v.to_dict(), "ranking": list(session.last_ranking)}
    except IntuitfError as exc:
        raise user_error(exc) from None
    finally:
        await session.aclose()


@router.post("/runs/{name}/prefer", response_model=VerdictOut)
async def prefer(request: Request, name: str, body: PreferIn) -> dict:
    return await _human(request, name, lambda s: s.prefer(body.better, body.worse))


@router.post("/runs/{name}/best", response_model=VerdictOut)
async def best_of(request: Request, name: str, body: BestIn) -> dict:
    return await _human(request, name, lambda s: s.choose_best(body.best, body.among))


@router.post("/runs/{name}/worst", response_model=VerdictOut)
async def worst_of(request: Request, name: str, body: WorstIn) -> dict:
    return await _human(request, name, lambda s: s.choose_worst(body.worst, body.among))


@router.post("/runs/{name}/undo", response_model=VerdictOut)
async def undo(request: Request, name: str, body: UndoIn | None = None) -> dict:
    vid = body.id if body is not None else None
    return await _human(request, name, lambda s: s.undo_verdict(vid))


# -- what the judge said -------------------------------------------------------------------------
def _match_out(m: dict, source: str = "model") -> dict:
    v = m.get("verdict") or {}
    return {
        "round": m.get("round"),
        "first": m.get("first"),
        "second": m.get("second"),
        "winner": v.get("overall", m.get("winner")),
        "p_first": v.get("p_first", m.get("p_first")),
        "per_aspect": v.get("per_aspect", m.get("per_aspect", {})),
        "reasons": v.get("rationale", m.get("reasons", {})),
        "error": v.get("error", m.get("error")),
        "cached": v.get("cached", m.get("cached", False)),
        "source": source,
    }


def _matches(web, name: str, generation: int | None) -> list[dict]:
    from intuitf.session import RunDirectory
    from intuitf.session.events import read_events

    rd = RunDirectory(web.store.path_of(name))
    entries = list(rd.iter_journal())
    gens = {e["generation"]: e for e in entries
            if e.get("type") == "generation" and isinstance(e.get("generation"), int)}  # fmt: skip
    live = web.registry.get(name)
    if generation is None:
        generation = max(gens) if gens else 0
        if live is not None:
            generation = max(generation, live.session.snapshot().generation)
    out: list[dict] = []
    ids: set[str] = set()
    if generation in gens:
        out = [_match_out(m) for m in gens[generation].get("matches", [])]
        ids = {c["id"] for c in gens[generation].get("candidates", [])}
    else:  # the generation in progress: from the events so far
        events = live.session.events.since(0) if live is not None else read_events(rd.events)
        for e in events:
            if e.type == "match_judged" and e.data.get("generation") == generation:
                out.append(_match_out(e.data))
            elif e.type == "generation_started" and e.data.get("generation") == generation:
                out = []
    human: dict[int, dict] = {}
    for e in entries:
        if e.get("type") == "human" and isinstance(e.get("verdict"), dict):
            human[int(e["verdict"].get("id", 0))] = e["verdict"]
    for v in human.values():
        games = v.get("games") or []
        if ids and not any(g[0] in ids or g[1] in ids for g in games):
            continue
        for g in games:
            out.append(
                {
                    "round": None, "first": g[0], "second": g[1], "winner": "first",
                    "p_first": 1.0, "per_aspect": {}, "reasons": {"note": v.get("note", "")},
                    "error": None, "cached": False, "source": "human",
                    "verdict_id": v.get("id"), "kind": v.get("kind"), "undone": v.get("undone"),
                }
            )  # fmt: skip
    return out


@router.get("/runs/{name}/matches")
def matches(
    request: Request, name: str, generation: int | None = Query(None, ge=0)
) -> list[dict[str, Any]]:
    web = state(request)
    _run_dir(web, name)
    return _matches(web, name, generation)


@router.get(
    "/runs/{name}/generations/{g}/thumbnail",
    response_class=FileResponse,
    responses={200: {"content": {"image/png": {}}}},
)
def thumbnail(request: Request, name: str, g: int) -> FileResponse:
    web = state(request)
    run_dir = _run_dir(web, name)
    if not 0 <= g < 1_000_000:
        raise ApiError(404, f"Run {name!r} has no generation {g}.")
    path = run_dir / "generations" / f"gen{g:03d}-best.png"
    if not path.is_file():
        raise ApiError(404, f"Run {name!r} has no picture of generation {g}.")
    return FileResponse(path, media_type="image/png")


@router.get(
    "/runs/{name}/events",
    response_class=StreamingResponse,
    responses={200: {"content": {"text/event-stream": {}}}},
)
async def events(
    request: Request,
    name: str,
    since: int | None = Query(None, ge=0),
    last_event_id: str | None = Header(None, alias="Last-Event-ID"),
) -> StreamingResponse:
    from intuitf.web.stream import run_events

    web = state(request)
    await asyncio.to_thread(_run_dir, web, name)
    start = since or 0
    if last_event_id is not None and last_event_id.strip().isdigit():
        start = max(start, int(last_event_id.strip()))
    return StreamingResponse(
        run_events(web, name, start, web.sse_keepalive),
        media_type="text/event-stream",
        headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"},
    )


def _run_view(web, name: str) -> dict[str, Any]:
    """The run's judging camera (a sketch is drawn over that view), its volume's id in the
    server's list (None when the run's volume is not among them) and the voxel size [x, y, z]
    it was made with (None if unrecorded): the volume may since have been given another."""
    from intuitf.render import Camera
    from intuitf.session import RunDirectory

    try:
        record = RunDirectory(web.store.path_of(name)).read_run()
    except IntuitfError:
        return {"camera": Camera().to_dict(), "volume_id": None, "spacing": None}
    camera = (record.get("settings") or {}).get("camera") or Camera().to_dict()
    source = ((record.get("spec") or {}).get("volume") or {}).get("source")
    volume_id = next((e.id for e in web.catalog.entries() if source and e.source == source), None)
    spacing = (record.get("volume") or {}).get("spacing_xyz")
    return {"camera": camera, "volume_id": volume_id, "spacing": spacing}
