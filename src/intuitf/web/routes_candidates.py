"""Candidates by run-qualified id: their TF, pictures, pick and feature views, hand edits and
exports."""

from __future__ import annotations

import asyncio
import json
from dataclasses import replace
from typing import Any, Literal

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field

from intuitf.errors import IntuitfError
from intuitf.session.scheduler import INTERACTIVE, render_scheduler
from intuitf.web.common import (
    ApiError,
    background_of,
    camera_of,
    check_candidate_id,
    check_run_name,
    check_size,
    data_url_png,
    encode_png,
    mask_overlay,
    state,
    tf_of,
    user_error,
)
from intuitf.web.schema import COMMON

router = APIRouter(prefix="/api", tags=["candidates"], responses=COMMON)

PNG = {200: {"content": {"image/png": {}}, "description": "A PNG picture."}}


class _In(BaseModel):
    model_config = ConfigDict(extra="forbid")


class PickIn(_In):
    camera: dict[str, Any] | None = None
    x: int
    y: int
    size: int = 256
    shaded: bool = True
    background: list[float] | None = None
    whole: bool = Field(
        False, description="Select every feature that makes the pixel, not only the smallest."
    )


class PickOut(BaseModel):
    index: int | None
    visible: list[list[float]] = Field(description="[index, share at the pixel, area in pixels]")
    selected: list[int] = Field(
        default_factory=list, description="The features the click selects (mask: their pixels)."
    )
    mask: str | None


class FeaturesIn(_In):
    camera: dict[str, Any] | None = None
    size: int = 256
    shaded: bool = True
    background: list[float] | None = None


class FeatureOut(BaseModel):
    index: int
    image: str


class EditIn(_In):
    parent: str = Field(..., description="RUN/gGGG-NNN")
    tf: dict[str, Any]


class EditOut(BaseModel):
    qid: str


def _qid(run: str, cid: str) -> str:
    return f"{check_run_name(run)}/{check_candidate_id(cid)}"


async def _candidate_and_volume(web, qid: str):
    info = await asyncio.to_thread(web.candidate, qid)
    volume = await asyncio.to_thread(web.volume_of_run, info.run)
    return info, volume


@router.get("/candidates/{run}/{cid}")
def candidate(request: Request, run: str, cid: str) -> dict[str, Any]:
    return state(request).candidate(_qid(run, cid)).to_dict()


@router.get("/candidates/{run}/{cid}/image", response_class=Response, responses=PNG)
async def candidate_image(
    request: Request, run: str, cid: str, size: int | None = Query(None, ge=16, le=1024)
) -> Response:
    """The candidate from its run's judging camera (with the run's shading and background)."""
    from intuitf.render import Camera

    web = state(request)
    qid = _qid(run, cid)
    rs = await asyncio.to_thread(web.run_settings, run)
    size = size or rs.image_size
    key = (qid, size)
    data = web.images.get_(key)
    if data is None:
        info, volume = await _candidate_and_volume(web, qid)
        camera = Camera.from_dict(rs.camera) if rs.camera else Camera()
        vr = web.view_renderer(volume, tuple(rs.background))
        image = await render_scheduler().run(
            lambda: vr.view(info.tf, camera, size, rs.shading), INTERACTIVE
        )
        data = await asyncio.to_thread(encode_png, image)
        web.images.put(key, data)
    return Response(
        data, media_type="image/png", headers={"Cache-Control": "private, max-age=3600"}
    )


def check_pick(body: PickIn):
    """The camera and size of a pick request (422 for a pixel outside the view)."""
    camera, size = camera_of(body.camera), check_size(body.size)
    if not (0 <= body.x < size and 0 <= body.y < size):
        raise ApiError(
            422,
            f"Pixel ({body.x}, {body.y}) is outside the {size}×{size} view.",
            "Give x and y from the top-left corner, within the view's size.",
        )
    return camera, size


async def pick_result(web, tf, volume, body: PickIn, camera, size: int) -> dict:
    """What a click at ``(body.x, body.y)`` picks of ``tf`` over ``volume``."""
    vr = web.view_renderer(volume, background_of(body.background))
    try:
        result = await render_scheduler().run(
            lambda: vr.pick(tf, camera, body.x, body.y, size, body.shaded, whole=body.whole),
            INTERACTIVE,
        )
    except IntuitfError as exc:
        raise user_error(exc) from None
    mask = None
    if result.mask is not None:
        mask = await asyncio.to_thread(lambda: data_url_png(mask_overlay(result.mask)))
    return {
        "index": result.index,
        "visible": [[int(i), float(share), int(area)] for i, share, area in result.visible],
        "selected": [int(i) for i in result.selected],
        "mask": mask,
    }


@router.post("/candidates/{run}/{cid}/pick", response_model=PickOut)
async def pick(request: Request, run: str, cid: str, body: PickIn) -> dict:
    web = state(request)
    camera, size = check_pick(body)
    info, volume = await _candidate_and_volume(web, _qid(run, cid))
    return await pick_result(web, info.tf, volume, body, camera, size)


async def feature_tiles(web, tf, volume, body: FeaturesIn) -> list[dict]:
    """Each Gaussian of ``tf`` rendered alone over ``volume``, as PNG data URLs."""
    camera, size = camera_of(body.camera), check_size(body.size)
    vr = web.view_renderer(volume, background_of(body.background))
    images = await render_scheduler().run(
        lambda: vr.features(tf, camera, size, body.shaded), INTERACTIVE
    )
    urls = await asyncio.to_thread(lambda: [data_url_png(im) for im in images])
    return [{"index": i, "image": u} for i, u in enumerate(urls)]


@router.post("/candidates/{run}/{cid}/features", response_model=list[FeatureOut])
async def features(request: Request, run: str, cid: str, body: FeaturesIn) -> list[dict]:
    web = state(request)
    info, volume = await _candidate_and_volume(web, _qid(run, cid))
    return await feature_tiles(web, info.tf, volume, body)


@router.post("/edits", response_model=EditOut, status_code=201)
async def save_edit(request: Request, body: EditIn) -> dict:
    web = state(request)
    tf = tf_of(body.tf)
    run, sep, cid = body.parent.partition("/")
    if not sep:
        raise ApiError(404, f"{body.parent[:80]!r} is not a candidate id.", "Use RUN/gGGG-NNN.")
    qid = _qid(run, cid)
    await asyncio.to_thread(web.candidate, qid)  # 404 for an unknown parent
    async with web.create_lock:
        try:
            new = await asyncio.to_thread(web.store.save_edit, qid, tf)
        except IntuitfError as exc:
            raise user_error(exc) from None
    return {"qid": new}


_MEDIA = {
    "paraview": "application/json",
    "slicer": "text/plain",
    "vtk": "text/x-python",
    "1dt": "text/plain",
    "json": "application/json",
    "png": "image/png",
}


@router.get(
    "/export/{run}/{cid}",
    response_class=Response,
    responses={200: {"content": {m: {} for m in sorted(set(_MEDIA.values()))}}},
)
async def export(
    request: Request,
    run: str,
    cid: str,
    to: Literal["paraview", "slicer", "vtk", "1dt", "json", "png"] = "json",
    size: int = Query(512, ge=16, le=2048),
    camera: str | None = Query(
        None, max_length=2000, description="PNG only: the view's camera as JSON (default: judging)"
    ),
) -> Response:
    """The candidate's TF as a download for another tool (in the data's own units)."""
    from intuitf.render import Camera
    from intuitf.tf.export import EXPORT_FORMATS, export_tf

    web = state(request)
    qid = _qid(run, cid)
    info = await asyncio.to_thread(web.candidate, qid)
    record = await asyncio.to_thread(web.record, run)
    summary = record.get("volume") or {}
    vr_ = summary.get("value_range")
    value_range = (float(vr_[0]), float(vr_[1])) if vr_ and len(vr_) == 2 else None
    spacing = summary.get("spacing_xyz") or [1.0]
    tf = replace(info.tf.unfreeze(), value_range=value_range, name=f"{run}-{cid}")
    stem = f"{run}-{cid}"
    if to == "png":
        rs = await asyncio.to_thread(web.run_settings, run)
        volume = await asyncio.to_thread(web.volume_of_run, run)
        if camera is not None:
            try:
                view_camera = camera_of(json.loads(camera))
            except ValueError:
                raise ApiError(
                    422, "camera must be a JSON object.", "Send {azimuth, ...}."
                ) from None
        else:
            view_camera = Camera.from_dict(rs.camera) if rs.camera else Camera()
        vr = web.view_renderer(volume, tuple(rs.background))
        image = await render_scheduler().run(
            lambda: vr.view(info.tf, view_camera, size, rs.shading), INTERACTIVE
        )
        data, filename = await asyncio.to_thread(encode_png, image), f"{stem}.png"
    elif to == "json":
        data, filename = tf.to_json().encode(), f"{stem}.tf.json"
    else:
        try:
            text = export_tf(tf, to, unit_distance=float(min(spacing)))
        except IntuitfError as exc:
            raise user_error(exc) from None
        data, filename = text.encode(), stem + EXPORT_FORMATS[to]
    return Response(
        data,
        media_type=_MEDIA[to],
        headers={"Content-Disposition": f'attachment; filename="{filename}"'},
    )
