"""``/api/view``: frames of a volume view over one WebSocket, newest request wins.

The page sends a request whenever the camera (or TF, size, shading) changes::

    {req, target: {candidate: "RUN/gGGG-NNN"} | {volume: ID, tf: TF JSON, run?: NAME},
     camera, size, shaded, background, quality: "drag" | "full", highlight?: [indices]}

(``run``: a hand edit of that run's result, drawn on the run's own volume.)

and gets back a text header ``{req, width, height, format, ms, quality, wait_ms, render_ms}``
(``ms`` in all, of which ``wait_ms`` waiting for the render worker) followed at once by
one binary message with the picture (JPEG for ``drag`` at half size, at most 128 pixels; PNG
for ``full``). One frame is in flight per socket: a request that arrives while a frame
renders waits in a single slot, replacing any request already waiting there, so a fast drag
renders the first camera and then the newest, never a queue of stale ones. Renders go
through the process's render scheduler at interactive priority, ahead of the tournament's.
Errors come back as ``{req, error, hint}``.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from typing import Any

from fastapi import APIRouter, WebSocket, WebSocketDisconnect

from intuitf.errors import IntuitfError
from intuitf.session.scheduler import INTERACTIVE, render_scheduler
from intuitf.web.common import (
    ApiError,
    background_of,
    camera_of,
    check_run_name,
    check_size,
    encode_jpeg,
    encode_png,
    outline,
    render_rgb8,
    tf_of,
)

router = APIRouter()
log = logging.getLogger(__name__)

#: The longest request text read (a request is a few hundred characters; a TF a few KB).
MAX_MESSAGE = 256 * 1024

#: Largest side of a frame while dragging.
DRAG_MAX = 128
#: Sides a drag frame may shrink to when the machine is slow (adaptive level of detail).
DRAG_LEVELS = (128, 96, 64)
#: Render time a drag frame aims at (ms): the side is chosen from the last frames' speed.
DRAG_BUDGET_MS = 40.0


class ViewSocket:
    """One socket's state: the frame in flight and the one request waiting for it."""

    def __init__(self, ws: WebSocket, web) -> None:
        self.ws = ws
        self.web = web
        self.busy = False
        self.pending: dict | None = None
        self.send_lock = asyncio.Lock()
        self.task: asyncio.Task | None = None
        self._tfs: dict[str, Any] = {}
        self._run_volumes: dict[str, Any] = {}  # a run's volume, for hand edits of its results
        #: Recent render time per pixel of drag frames (ms), for the adaptive level of detail.
        self._ms_per_px: float | None = None
        self.budget = getattr(web, "drag_budget_ms", DRAG_BUDGET_MS)

    async def serve(self) -> None:
        try:
            while True:
                message = await self.ws.receive()
                if message["type"] == "websocket.disconnect":
                    break
                text = message.get("text")
                if text is None:
                    await self._error(None, "Send requests as JSON text.", None)
                    continue
                if len(text) > MAX_MESSAGE:
                    await self._error(None, f"A request is at most {MAX_MESSAGE} characters.", None)
                    continue
                try:
                    req = json.loads(text)
                    if not isinstance(req, dict):
                        raise ValueError("not an object")
                except (ValueError, RecursionError):  # RecursionError: nesting too deep
                    await self._error(None, "A request must be a JSON object.", None)
                    continue
                if self.busy:
                    self.pending = req  # newest wins: an older waiting request is dropped
                else:
                    self.busy = True
                    self.task = asyncio.create_task(self._render_loop(req))
        except WebSocketDisconnect:
            pass
        finally:
            if self.task is not None:
                self.task.cancel()

    async def _render_loop(self, req: dict) -> None:
        try:
            while req is not None:
                try:
                    header, data = await self._frame(req)
                    async with self.send_lock:
                        await self.ws.send_text(json.dumps(header))
                        await self.ws.send_bytes(data)
                except ApiError as exc:
                    await self._error(req.get("req"), exc.detail, exc.hint)
                except IntuitfError as exc:
                    await self._error(req.get("req"), exc.message, exc.hint)
                except (WebSocketDisconnect, asyncio.CancelledError):
                    raise
                except Exception as exc:  # a request no check foresaw: say so, keep the socket
                    log.warning("view request failed: %r", exc, exc_info=True)
                    await self._error(
                        req.get("req"),
                        f"The view could not be rendered ({type(exc).__name__}).",
                        "Check the request's fields; see the server's log.",
                    )
                req, self.pending = self.pending, None
        except (WebSocketDisconnect, RuntimeError, asyncio.CancelledError):
            pass
        finally:
            self.busy = False

    def _drag_size(self, want: int) -> int:
        """The side of the next drag frame: ``want``, or a smaller level when the last drag
        frames took longer than the budget (they grow back when the machine is faster)."""
        if not self.budget or self._ms_per_px is None:
            return want
        for side in DRAG_LEVELS:
            if side <= want and side * side * self._ms_per_px <= self.budget:
                return side
        return min(want, DRAG_LEVELS[-1])

    async def _error(self, req, error: str, hint: str | None) -> None:
        async with self.send_lock:
            try:
                await self.ws.send_text(json.dumps({"req": req, "error": error, "hint": hint}))
            except (WebSocketDisconnect, RuntimeError):
                pass

    async def _target(self, target: Any):
        """(tf, volume) of a request's target."""
        web = self.web
        if not isinstance(target, dict):
            raise ApiError(422, "A target is {candidate: RUN/gGGG-NNN} or {volume: ID, tf: ...}.")
        if "candidate" in target:
            qid = str(target["candidate"])
            got = self._tfs.get(qid)
            if got is None:
                info = await asyncio.to_thread(web.candidate, qid)
                volume = await asyncio.to_thread(web.volume_of_run, info.run)
                got = self._tfs[qid] = (info.tf, volume)
            return got
        if "volume" in target:
            entry = web.catalog.get(target["volume"])
            tf = tf_of(target.get("tf"))
            if target.get("run"):
                # A hand edit of a run's result: on the run's own volume (the voxel size it
                # was made with, which the catalog's may no longer be).
                run = str(target["run"])
                check_run_name(run)
                volume = self._run_volumes.get(run)
                if volume is None:
                    volume = await asyncio.to_thread(web.volume_of_run, run)
                    self._run_volumes[run] = volume
                return tf, volume
            volume = await asyncio.to_thread(web.catalog.load, entry.id)
            return tf, volume
        raise ApiError(422, "A target is {candidate: RUN/gGGG-NNN} or {volume: ID, tf: ...}.")

    async def _frame(self, req: dict) -> tuple[dict, bytes]:
        t0 = time.perf_counter()
        quality = req.get("quality", "full")
        if quality not in ("drag", "full"):
            raise ApiError(422, f"quality must be 'drag' or 'full', got {quality!r}.")
        try:
            size = check_size(req.get("size", 256))
        except (TypeError, ValueError):
            raise ApiError(422, "size must be a whole number of pixels.") from None
        camera = camera_of(req.get("camera"))
        shaded = bool(req.get("shaded", True))
        bg = background_of(req.get("background"))
        highlight = req.get("highlight") or []
        if not isinstance(highlight, list) or not all(
            isinstance(i, int) and not isinstance(i, bool) for i in highlight
        ):
            raise ApiError(422, "highlight is a list of Gaussian indices (whole numbers).")
        tf, volume = await self._target(req.get("target"))
        vr = self.web.view_renderer(volume, bg)
        if quality == "drag":
            size = self._drag_size(min(DRAG_MAX, max(16, size // 2)))
            drag = self.web.drag_renderer(volume, bg, size, shaded)
            image, wait, ms = await _on_worker(lambda: render_rgb8(drag, tf, camera))
            per_px = ms / (size * size)
            self._ms_per_px = (
                per_px if self._ms_per_px is None else (0.5 * self._ms_per_px + 0.5 * per_px)
            )
            # A JPEG of at most 128² takes well under a millisecond: no thread hop for it.
            data, fmt = encode_jpeg(image), "jpeg"
        else:
            image, wait, ms = await _on_worker(
                lambda: _full(vr, tf, camera, size, shaded, highlight)
            )
            data, fmt = await asyncio.to_thread(encode_png, image), "png"
        header = {
            "req": req.get("req"),
            "width": int(image.shape[1]),
            "height": int(image.shape[0]),
            "format": fmt,
            "ms": round((time.perf_counter() - t0) * 1000.0, 1),
            "quality": quality,
            "wait_ms": round(wait, 1),
            "render_ms": round(ms, 1),
        }
        return header, data


async def _on_worker(fn):
    """``fn()`` on the render worker at interactive priority: (result, ms waited for the
    worker, ms it took)."""
    submitted = time.perf_counter()

    def job():
        start = time.perf_counter()
        out = fn()
        return out, (start - submitted) * 1000.0, (time.perf_counter() - start) * 1000.0

    return await render_scheduler().run(job, INTERACTIVE)


def _full(vr, tf, camera, size: int, shaded: bool, highlight: list[int]):
    """A still; with features to highlight, from the view's sample cache (which a click's
    pick from the same camera then shares), else ray-marched directly (cheaper than
    sampling the volume into a cache)."""
    from intuitf.session.views import VISIBLE_SHARE

    valid = [i for i in highlight if 0 <= i < len(tf)]
    if not valid:
        return render_rgb8(vr.renderer(size, shaded), tf, camera)
    cache = vr.sample_cache(camera, size, shaded)
    image = cache.render(tf)
    att = cache.attribution(tf)
    return outline(image, (att[valid] >= VISIBLE_SHARE).any(axis=0))


@router.websocket("/api/view")
async def view(ws: WebSocket) -> None:
    await ws.accept()
    await ViewSocket(ws, ws.app.state.web).serve()
