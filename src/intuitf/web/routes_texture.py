"""``GET /api/volumes/{id}/texture``: a volume's voxels as the page's 3-D texture.

The page renders the current transfer function itself (WebGL2); it fetches each volume once
and the browser keeps it (an ``ETag`` that changes with the file, ``Cache-Control: private,
no-cache``: a second visit costs a 304). The body is the bare voxel array, x fastest, then y,
then z, in one of two formats the response's headers name:

- ``r8``: one byte per voxel for 8-bit data, the original integer values. The normalised
  value the transfer function reads is ``byte / 255 * scale + offset`` (``X-Volume-Map``), a
  linear map, so it commutes with the texture's trilinear filtering and the page classifies
  exactly the values the server's renderer does.
- ``r16f``: IEEE half floats of the normalised value for wider data (16-bit, float). WebGL2
  filters ``R16F`` textures in its core (16-bit normalised integer textures need an extension
  few browsers have), and a half float resolves values to 1/2048 near 1, about one entry of a
  4096-entry lookup table.

``max_bytes`` and ``max_side`` let the page ask for what its 3-D texture limits and memory
allow: the server then keeps every ``step``-th voxel along each axis (the smallest step that
fits) and says so in ``X-Volume-Step``; spacing grows by the same factor, so the picture keeps
its proportions and, with opacity corrected per unit length, its look.
"""

from __future__ import annotations

import asyncio
import hashlib
import math
import os
import threading
from collections import OrderedDict

import numpy as np
from fastapi import APIRouter, Query, Request
from fastapi.responses import Response

from intuitf.web.common import ApiError, state
from intuitf.web.schema import COMMON

router = APIRouter(prefix="/api", tags=["volumes"], responses=COMMON)

#: Version of the byte layout: part of the ETag, so a change never meets a stale browser copy.
LAYOUT_VERSION = 1
#: Encoded textures kept in memory (a page that reloads, or two pages, share them).
_KEEP = 2
_cache: OrderedDict[str, tuple[bytes, dict[str, str]]] = OrderedDict()
_lock = threading.Lock()

RAW = {
    200: {
        "content": {"application/octet-stream": {}},
        "description": "The voxels (see the X-Volume-* headers for their layout).",
    },
    304: {"description": "The browser's copy is current."},
}


def texture_format(volume) -> str:
    """``"r8"`` for 8-bit data (whose 256-entry LUT a byte resolves), ``"r16f"`` otherwise."""
    return (
        "r8"
        if volume.lut_size == 256 and volume.original_dtype in ("uint8", "int8", "bool")
        else "r16f"
    )


def choose_step(
    dims: tuple[int, int, int], bytes_per_voxel: int, max_bytes: int, max_side: int
) -> int:
    """The smallest stride that brings every side within ``max_side`` and the whole within
    ``max_bytes`` (at least 1)."""
    step = 1
    while True:
        d = [math.ceil(n / step) for n in dims]
        if max(d) <= max_side and d[0] * d[1] * d[2] * bytes_per_voxel <= max_bytes:
            return step
        if min(d) <= 2:
            return step
        step += 1


def encode_texture(volume, fmt: str, step: int) -> tuple[bytes, dict[str, str]]:
    """The texture's bytes and the headers that describe them (no I/O)."""
    data = volume.data
    if step > 1:
        data = data[::step, ::step, ::step]
    lo, hi = (float(v) for v in volume.value_range)
    if fmt == "r8":
        # Back to the original integers: normalised = (k - lo) / (hi - lo).
        k = np.rint(data * (hi - lo) + lo)
        body = np.clip(k, 0, 255).astype(np.uint8).tobytes()
        scale, offset = 255.0 / (hi - lo), -lo / (hi - lo)
    else:
        body = np.ascontiguousarray(data, dtype="<f2").tobytes()
        scale, offset = 1.0, 0.0
    nz, ny, nx = data.shape
    sp = [float(s) * step for s in volume.spacing]
    headers = {
        "X-Volume-Format": fmt,
        "X-Volume-Dims": f"{nx},{ny},{nz}",
        "X-Volume-Full-Dims": ",".join(str(n) for n in volume.dims),
        "X-Volume-Spacing": ",".join(repr(s) for s in sp),
        "X-Volume-Step": str(step),
        "X-Volume-Map": f"{scale!r},{offset!r}",
        "X-Volume-Lut-Size": str(volume.lut_size),
        "X-Volume-Dtype": str(volume.original_dtype),
    }
    return body, headers


def _etag(entry, step_key: str) -> str:
    """Changes with the file (size, modification time) and the request's limits."""
    stamp = "builtin"
    if not entry.source.startswith("builtin:"):
        try:
            st = os.stat(entry.source)
            stamp = f"{st.st_size}-{st.st_mtime_ns}"
        except OSError:
            stamp = "missing"
    key = f"{LAYOUT_VERSION}|{entry.source}|{sorted(entry.options.items())}|{stamp}|{step_key}"
    return '"' + hashlib.sha1(key.encode()).hexdigest()[:20] + '"'


@router.get("/volumes/{volume_id}/texture", response_class=Response, responses=RAW)
async def volume_texture(
    request: Request,
    volume_id: str,
    max_bytes: int = Query(1 << 30, ge=1 << 16, description="largest body the page takes"),
    max_side: int = Query(2048, ge=16, le=16384, description="the page's MAX_3D_TEXTURE_SIZE"),
) -> Response:
    web = state(request)
    entry = web.catalog.get(volume_id)
    etag = _etag(entry, f"{max_bytes}|{max_side}")
    cache_headers = {"ETag": etag, "Cache-Control": "private, no-cache"}
    if etag in (request.headers.get("if-none-match") or ""):
        return Response(status_code=304, headers=cache_headers)
    with _lock:
        got = _cache.get(etag)
        if got is not None:
            _cache.move_to_end(etag)
    if got is None:
        volume = await asyncio.to_thread(web.catalog.load, entry.id)
        fmt = texture_format(volume)
        step = choose_step(volume.dims, 1 if fmt == "r8" else 2, max_bytes, max_side)
        if min(math.ceil(n / step) for n in volume.dims) < 2:
            raise ApiError(
                422,
                f"{entry.name}: the volume does not fit the page's limits "
                f"({max_bytes} bytes, {max_side} per side).",
                "The view shows the server's pictures instead.",
            )
        got = await asyncio.to_thread(encode_texture, volume, fmt, step)
        with _lock:
            _cache[etag] = got
            while len(_cache) > _KEEP:
                _cache.popitem(last=False)
    body, headers = got
    return Response(
        body, media_type="application/octet-stream", headers={**headers, **cache_headers}
    )
