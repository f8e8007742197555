"""Volumes by id (list, upload, histogram), picture uploads, and the hand-edit TF preview."""

from __future__ import annotations

import asyncio
from typing import Any

from fastapi import APIRouter, File, Request, UploadFile
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field

from intuitf.session.scheduler import INTERACTIVE, render_scheduler
from intuitf.web.common import (
    ApiError,
    background_of,
    camera_of,
    check_size,
    encode_png,
    state,
    tf_of,
)
from intuitf.web.routes_candidates import (
    FeatureOut,
    FeaturesIn,
    PickIn,
    PickOut,
    check_pick,
    feature_tiles,
    pick_result,
)
from intuitf.web.schema import COMMON
from intuitf.web.security import TOO_LARGE_HINT, too_large

router = APIRouter(prefix="/api", tags=["volumes"], responses=COMMON)

PNG = {200: {"content": {"image/png": {}}, "description": "A PNG picture."}}


class VolumeOut(BaseModel):
    id: str
    name: str
    shape: list[int] | None = Field(None, description="[x, y, z]; null until first loaded")
    dtype: str | None = None
    source: str
    spacing: list[float] | None = Field(
        None, description="voxel size [x, y, z] set by serve --spacing or PATCH; null: the file's"
    )


class VolumePatch(BaseModel):
    model_config = ConfigDict(extra="forbid")
    spacing: list[float] | None = Field(
        ..., min_length=3, max_length=3, description="[x, y, z]; null: the file's own"
    )


class Material(BaseModel):
    mean: float
    width: float
    fraction: float


class Histogram(BaseModel):
    counts: list[float]
    value_range: list[float]
    materials: list[Material]


class UploadOut(BaseModel):
    id: str
    width: int
    height: int


class PreviewIn(BaseModel):
    volume: str
    tf: dict[str, Any]
    camera: dict[str, Any] | None = None
    size: int = 256
    shaded: bool = True
    background: list[float] | None = None


async def read_limited(upload: UploadFile, limit: int) -> bytes:
    """The upload's bytes, or 413 as soon as it passes ``limit``."""
    chunks, total = [], 0
    while True:
        chunk = await upload.read(1024 * 1024)
        if not chunk:
            break
        total += len(chunk)
        if total > limit:
            raise ApiError(413, too_large(limit), TOO_LARGE_HINT)
        chunks.append(chunk)
    return b"".join(chunks)


@router.get("/volumes", response_model=list[VolumeOut])
def list_volumes(request: Request) -> list[dict]:
    return [e.to_dict() for e in state(request).catalog.entries()]


@router.post("/volumes", response_model=VolumeOut, status_code=201)
async def upload_volume(request: Request, file: UploadFile = File(...)) -> dict:
    web = state(request)
    data = await read_limited(file, web.max_upload_bytes)
    entry = await asyncio.to_thread(web.catalog.save_upload, file.filename or "", data)
    return entry.to_dict()


@router.patch("/volumes/{volume_id}", response_model=VolumeOut)
def set_volume(request: Request, volume_id: str, body: VolumePatch) -> dict:
    """Set a file volume's voxel size (a raw file has none of its own): new runs use it."""
    return state(request).catalog.set_spacing(volume_id, body.spacing).to_dict()


@router.delete("/volumes/{volume_id}", status_code=204, response_class=Response)
async def delete_volume(request: Request, volume_id: str) -> Response:
    """Delete an uploaded volume that no run was made from."""
    web = state(request)
    entry = web.catalog.get(volume_id)
    used = await asyncio.to_thread(_runs_of_source, web, entry.source)
    await asyncio.to_thread(web.catalog.delete_upload, volume_id, used)
    return Response(status_code=204)


def _runs_of_source(web, source: str) -> list[str]:
    from intuitf.errors import IntuitfError
    from intuitf.session import RunDirectory

    out = []
    for name in web.store.names():
        try:
            record = RunDirectory(web.store.path_of(name)).read_run()
        except IntuitfError:
            continue
        if ((record.get("spec") or {}).get("volume") or {}).get("source") == source:
            out.append(name)
    return out


class StructureOut(BaseModel):
    id: int
    name: str | None
    shape: str
    position: str
    outer: bool
    share: float
    value_range: list[float]


@router.get("/volumes/{volume_id}/structures", response_model=list[StructureOut])
async def structures(request: Request, volume_id: str) -> list[dict]:
    """The volume's structures (its materials split into 3-D parts, with the names a model
    gave them where it did): what the Features view labels each feature with."""
    web = state(request)
    entry = web.catalog.get(volume_id)
    return await asyncio.to_thread(web.catalog.structures, entry.id)


@router.get("/volumes/{volume_id}/camera")
async def volume_camera(request: Request, volume_id: str) -> dict[str, Any]:
    """``{camera}``: the view a new run of the volume judges from when nothing chooses one
    (upright, showing its structures), the same as every front end's; the page previews the
    volume from it."""
    web = state(request)
    entry = web.catalog.get(volume_id)  # 404 before any work
    return {"camera": await asyncio.to_thread(web.catalog.camera, entry.id)}


@router.get("/volumes/{volume_id}/histogram", response_model=Histogram)
async def histogram(request: Request, volume_id: str) -> dict:
    web = state(request)
    web.catalog.get(volume_id)  # 404 before any work
    return await asyncio.to_thread(web.catalog.histogram, volume_id)


@router.post("/uploads", response_model=UploadOut, status_code=201)
async def upload_picture(request: Request, file: UploadFile = File(...)) -> dict:
    web = state(request)
    data = await read_limited(file, min(web.max_upload_bytes, 64 * 1024 * 1024))
    return await asyncio.to_thread(web.pictures.save, data)


class VolumePickIn(PickIn):
    tf: dict[str, Any]


class VolumeFeaturesIn(FeaturesIn):
    tf: dict[str, Any]


@router.post("/volumes/{volume_id}/pick", response_model=PickOut)
async def volume_pick(request: Request, volume_id: str, body: VolumePickIn) -> dict:
    """A click on a volume's preview (a TF not yet in any run): the feature under it."""
    web = state(request)
    entry = web.catalog.get(volume_id)
    tf = tf_of(body.tf)
    camera, size = check_pick(body)
    volume = await asyncio.to_thread(web.catalog.load, entry.id)
    return await pick_result(web, tf, volume, body, camera, size)


@router.post("/volumes/{volume_id}/features", response_model=list[FeatureOut])
async def volume_features(request: Request, volume_id: str, body: VolumeFeaturesIn) -> list[dict]:
    """Each Gaussian of a preview's TF rendered alone over the volume."""
    web = state(request)
    entry = web.catalog.get(volume_id)
    tf = tf_of(body.tf)
    volume = await asyncio.to_thread(web.catalog.load, entry.id)
    return await feature_tiles(web, tf, volume, body)


@router.post("/tf/preview", response_class=Response, responses=PNG)
async def tf_preview(request: Request, body: PreviewIn) -> Response:
    web = state(request)
    entry = web.catalog.get(body.volume)
    tf = tf_of(body.tf)
    camera = camera_of(body.camera)
    size = check_size(body.size)
    bg = background_of(body.background)
    volume = await asyncio.to_thread(web.catalog.load, entry.id)
    vr = web.view_renderer(volume, bg)
    image = await render_scheduler().run(
        lambda: vr.view(tf, camera, size, body.shaded), INTERACTIVE
    )
    data = await asyncio.to_thread(encode_png, image)
    return Response(data, media_type="image/png", headers={"Cache-Control": "no-store"})
