"""``create_app``: the FastAPI application of ``intuitf serve``.

The app serves the page (static ES modules under ``web/static``) and a JSON API whose OpenAPI
schema is the contract with the page. It drives runs only through the Session service
(:mod:`intuitf.session`): ``RunStore`` for the history, ``Session.open/resume/branch`` for
runs, the session's events for progress and its view renderer for frames.
"""

from __future__ import annotations

import asyncio
import logging
import os
import threading
from collections import OrderedDict
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from intuitf.errors import IntuitfError, RunBusy, RunLocked, TooManyRuns
from intuitf.session import RunStore
from intuitf.session.live import RunRegistry
from intuitf.web.common import ApiError
from intuitf.web.security import DEFAULT_HOSTS, SecurityMiddleware, new_token
from intuitf.web.uploads import PictureStore
from intuitf.web.volumes import VolumeCatalog

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).parent / "static"
#: Hidden folder in the runs folder for uploads (RunStore lists only folders with a run.json).
UPLOADS = ".uploads"
DEFAULT_MAX_UPLOAD = 512 * 1024 * 1024
#: Step along the rays of a drag frame, in voxels (a still's is 0.5).
DRAG_STEP = 1.0

#: Evaluator specs the page offers as examples.
EVALUATOR_EXAMPLES = [
    "metric",
    "openai:gpt-4o",
    "gemini:gemini-2.0-flash",
    "openrouter:openai/gpt-4o",
    "ollama:llava",
    "http://127.0.0.1:8000/v1",
]


class _LRU(OrderedDict):
    def __init__(self, size: int) -> None:
        super().__init__()
        self.size = size
        self.lock = threading.Lock()

    def get_(self, key):
        with self.lock:
            v = self.get(key)
            if v is not None:
                self.move_to_end(key)
            return v

    def put(self, key, value) -> None:
        with self.lock:
            self[key] = value
            self.move_to_end(key)
            while len(self) > self.size:
                self.popitem(last=False)


class WebState:
    """What the routes share: the run store, live runs, volumes, uploads and render caches."""

    def __init__(
        self,
        runs_dir: Path,
        catalog: VolumeCatalog,
        *,
        evaluator: str,
        token: str,
        max_upload_bytes: int,
        default_settings: dict | None,
        sse_keepalive: float,
        max_live_runs: int,
        drag_budget_ms: float | None = 40.0,
        device: str | None = None,
        judge_options: dict | None = None,
    ) -> None:
        self.runs_dir = runs_dir
        #: Options of new runs' model judges (``serve --max-concurrency`` ...), unless a run's
        #: spec gives its own judge.
        self.judge_options = dict(judge_options or {})
        #: Where views of volumes with no live run render (``serve --device``; None: each
        #: volume's own device, "auto" unless a run named one).
        self.device = device
        self.store = RunStore(runs_dir)
        self.registry = RunRegistry(max_live_runs)
        self.catalog = catalog
        self.pictures = PictureStore(runs_dir / UPLOADS / "pictures")
        self.evaluator = evaluator
        self.token = token
        self.max_upload_bytes = max_upload_bytes
        self.default_settings = dict(default_settings or {})
        self.sse_keepalive = sse_keepalive
        #: Render time a drag frame aims at (ms); None: always half the view's size.
        self.drag_budget_ms = drag_budget_ms
        self._renderers = _LRU(12)
        self.candidates = _LRU(512)
        self.images = _LRU(256)
        self.create_lock = asyncio.Lock()
        #: Set when the server begins to stop: event streams end, runs are cancelled.
        self.stopping = False
        self._stream_stoppers: set = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._closing_task: asyncio.Task | None = None

    # -- stopping --------------------------------------------------------------------------
    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self.registry.bind(loop)

    def on_stop(self, fn) -> None:
        """Call ``fn()`` (on the server's loop) when the server begins to stop."""
        self._stream_stoppers.add(fn)

    def forget_stop(self, fn) -> None:
        self._stream_stoppers.discard(fn)

    def begin_shutdown(self) -> None:
        """End event streams and cancel runs at once (safe from a signal handler)."""
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        try:
            loop.call_soon_threadsafe(self._stop)
        except RuntimeError:
            pass

    def _stop(self) -> None:
        if self.stopping:
            return
        self.stopping = True
        for fn in list(self._stream_stoppers):
            try:
                fn()
            except Exception:
                pass
        self.registry._notify()
        self._closing_task = asyncio.ensure_future(self.registry.close_all())

    async def close(self) -> None:
        self._stop()
        if self._closing_task is not None:
            await self._closing_task
        await self.registry.close_all()

    # -- rendering helpers -----------------------------------------------------------------
    def _live_session_of(self, volume):
        """The live run's session that renders ``volume``, if one does."""
        for name in self.registry.names():
            live = self.registry.get(name)
            if live is not None and live.session.volume is volume:
                return live.session
        return None

    def device_for(self, volume) -> str | None:
        """Where views of ``volume`` render: its live run's device, else the server's."""
        session = self._live_session_of(volume)
        return session.settings.device if session is not None else self.device

    def view_renderer(self, volume, background=(0.0, 0.0, 0.0)):
        """A :class:`ViewRenderer` of ``volume`` on ``background``: the live run's own when a
        run of that volume and background is going (one sample cache for the run's views and
        the page's), else one kept per (volume, background, device). Renderers of a volume
        share its render context (gradient, block ranges), so these cost only their pictures."""
        from intuitf.session.views import ViewRenderer

        bg = tuple(round(float(c), 4) for c in background)
        session = self._live_session_of(volume)
        if session is not None:
            if tuple(round(float(c), 4) for c in session.settings.background) == bg:
                return session.views
        device = self.device_for(volume)
        key = (id(volume), bg, device)
        got = self._renderers.get_(key)
        if got is None or got[0] is not volume:
            got = (volume, ViewRenderer(volume, background=tuple(background), device=device))
            self._renderers.put(key, got)
        return got[1]

    def drag_renderer(self, volume, background, size: int, shading: bool):
        """A renderer for drag frames: ``size`` pixels, samples a voxel apart along each ray
        (half as dense as a still, as it has half the pixels; opacity is corrected for the
        step, so the picture looks the same, only coarser)."""
        from intuitf.render import VolumeRenderer

        device = self.device_for(volume)
        bg = tuple(round(float(c), 4) for c in background)
        key = ("drag", id(volume), bg, size, shading, device)
        got = self._renderers.get_(key)
        if got is None or got[0] is not volume:
            r = VolumeRenderer(volume, size=size, shading=shading, background=tuple(background),
                               sample_distance=DRAG_STEP, device=device)  # fmt: skip
            got = (volume, r)
            self._renderers.put(key, got)
        return got[1]

    def record(self, name: str) -> dict:
        """A run's run.json (404 when there is no such run; blocking)."""
        from intuitf.session import RunDirectory

        try:
            path = self.store.path_of(name)
        except IntuitfError:
            raise ApiError(
                404, f"There is no run {name[:80]!r}.", "Use a name from the run list."
            ) from None
        rd = RunDirectory(path)
        if not rd.exists():
            raise ApiError(404, f"There is no run {name[:80]!r}.", "Use a name from the run list.")
        try:
            return rd.read_run()
        except IntuitfError as exc:
            raise ApiError(422, exc.message, exc.hint) from None

    def run_settings(self, name: str):
        from intuitf.session import RunSettings

        return RunSettings.from_dict(self.record(name).get("settings", {}))

    def volume_of_run(self, name: str):
        """The volume of run ``name``: the live session's, else loaded from its spec (blocking)."""
        live = self.registry.get(name)
        if live is not None:
            return live.session.volume
        from intuitf.session.building import spec_of_record

        record = self.record(name)
        try:
            spec = spec_of_record(record)
        except IntuitfError as exc:
            raise ApiError(422, exc.message, exc.hint) from None
        if not spec.volume.source:
            raise ApiError(
                409,
                f"The run {name!r} was made from a volume in memory; its source is unknown.",
                "Open it from Python with the volume passed in.",
            )
        try:
            return self.catalog.load_spec(spec.volume)
        except IntuitfError as exc:
            raise ApiError(422, exc.message, exc.hint) from None

    def candidate(self, qid: str):
        """The :class:`CandidateInfo` of ``RUN/gGGG-NNN`` (404 if none; blocking)."""
        from intuitf.session.store import CandidateInfo
        from intuitf.web.common import parse_qid

        run, cid = parse_qid(qid)
        got = self.candidates.get_(qid)
        if got is not None:
            return got
        self.record(run)  # 404 for an unknown run
        try:
            info = self.store.candidate(qid)
        except IntuitfError as exc:
            live = self.registry.get(run)
            tf = live.session.snapshot().tfs.get(cid) if live is not None else None
            if tf is None:
                raise ApiError(404, exc.message, exc.hint) from None
            snap = live.session.snapshot()  # type: ignore[union-attr]
            return CandidateInfo(qid, run, cid, int(cid[1 : cid.index('-')]), snap.stage, tf,
                                 float(snap.ratings.get(cid, float("nan"))), 0)  # fmt: skip
        self.candidates.put(qid, info)
        return info


def _error_response(status: int, detail: str, hint: str | None = None, **extra) -> JSONResponse:
    body: dict[str, Any] = {"detail": detail}
    if hint:
        body["hint"] = hint
    body.update(extra)
    return JSONResponse(body, status_code=status)


def create_app(
    runs_dir: str | os.PathLike,
    volumes: list[str] | tuple[str, ...] = (),
    data_dir: str | os.PathLike | None = None,
    evaluator: str = "metric",
    token: str | None = None,
    allowed_hosts: list[str] | tuple[str, ...] | None = None,
    max_upload_bytes: int = DEFAULT_MAX_UPLOAD,
    *,
    max_dim: int | None = None,
    spacing: tuple[float, float, float] | None = None,
    default_settings: dict | None = None,
    sse_keepalive: float = 15.0,
    max_live_runs: int = 4,
    drag_budget_ms: float | None = 40.0,
    device: str | None = None,
    judge_options: dict | None = None,
) -> FastAPI:
    """The intuitf web app over the runs folder ``runs_dir``.

    ``volumes`` are offered beside the built-in phantom and the files under ``data_dir``;
    ``evaluator`` is the judge a run uses unless its spec names one; ``token`` is the access
    token (a fresh one if None: read it back from ``app.state.web.token``); ``allowed_hosts``
    are the Host header values served (``name`` for any port or ``name:port``; default
    127.0.0.1, localhost and [::1]); ``max_upload_bytes`` limits uploads. ``default_settings``
    fill in run settings a spec leaves out (tests use small ones). ``drag_budget_ms`` is the
    render time drag frames aim at (their side shrinks from 128 to 96 or 64 pixels on a slow
    machine; None keeps 128). ``device`` (auto, cpu or cuda) is where new runs and the views of
    volumes without a live run render (a run's views render on its own device).
    ``judge_options`` go to the model judge of new runs that name no judge of their own.
    """
    from intuitf import __version__
    from intuitf.web import (
        routes_candidates,
        routes_info,
        routes_runs,
        routes_texture,
        routes_volumes,
        view_socket,
    )

    runs_path = Path(runs_dir).expanduser().resolve()
    runs_path.mkdir(parents=True, exist_ok=True)
    token = token or new_token()
    catalog = VolumeCatalog(
        list(volumes),
        data_dir,
        upload_dir=runs_path / UPLOADS / "volumes",
        max_dim=max_dim,
        spacing=spacing,
    )
    web = WebState(
        runs_path,
        catalog,
        evaluator=evaluator,
        token=token,
        max_upload_bytes=int(max_upload_bytes),
        default_settings=(
            {"device": device, **(default_settings or {})} if device else default_settings
        ),
        sse_keepalive=float(sse_keepalive),
        max_live_runs=int(max_live_runs),
        drag_budget_ms=drag_budget_ms,
        judge_options=judge_options,
        device=device,
    )

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        web.bind(asyncio.get_running_loop())
        web.create_lock = asyncio.Lock()
        try:
            yield
        finally:
            await web.close()

    app = FastAPI(
        title="intuitf",
        version=__version__,
        description="Design transfer functions for direct volume rendering: runs, views, history.",
        lifespan=lifespan,
        # The schema is at /openapi.json; no Swagger page (its scripts would come from a CDN
        # that the page's own Content-Security-Policy refuses).
        docs_url=None,
        redoc_url=None,
    )
    app.state.web = web

    @app.exception_handler(ApiError)
    async def _api_error(request: Request, exc: ApiError):
        return JSONResponse(exc.body(), status_code=exc.status)

    @app.exception_handler(IntuitfError)
    async def _user_error(request: Request, exc: IntuitfError):
        return _error_response(422, exc.message, exc.hint)

    @app.exception_handler(RunBusy)
    @app.exception_handler(RunLocked)
    async def _conflict(request: Request, exc: IntuitfError):
        return _error_response(409, exc.message, exc.hint)

    @app.exception_handler(TooManyRuns)
    async def _too_many(request: Request, exc: TooManyRuns):
        return _error_response(429, exc.message, exc.hint)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError):
        errors = exc.errors()
        parts = []
        for err in errors[:5]:
            loc = ".".join(str(p) for p in err.get("loc", ()) if p != "body") or "request"
            parts.append(f"{loc}: {err.get('msg', 'invalid')}")
        return _error_response(
            422,
            "The request is not valid: " + "; ".join(parts) + ".",
            "Fix the fields named above.",
            errors=[{"loc": list(e.get("loc", ())), "msg": str(e.get("msg", ""))} for e in errors],
        )

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException):
        detail = exc.detail if isinstance(exc.detail, str) else "Request refused."
        headers = getattr(exc, "headers", None)
        if exc.status_code == 405:  # Allow names every method of the path, not one route's
            headers = {**(headers or {}), "Allow": ", ".join(_methods_of(request))}
        return JSONResponse({"detail": detail}, status_code=exc.status_code, headers=headers)

    def _methods_of(request: Request) -> list[str]:
        """The methods the schema declares for the request's path."""
        import re

        methods: set[str] = set()
        for template, ops in app.openapi().get("paths", {}).items():
            pattern = "^" + re.sub(r"\\\{[^}]+\\\}", "[^/]+", re.escape(template)) + "$"
            if re.match(pattern, request.url.path):
                methods |= {m.upper() for m in ops}
        return sorted(methods) or ["GET"]

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception):  # pragma: no cover - a bug
        log.exception("unexpected error in %s %s", request.method, request.url.path)
        return _error_response(
            500, f"The server failed ({type(exc).__name__}).", "See the server's log."
        )

    for module in (
        routes_info,
        routes_volumes,
        routes_texture,
        routes_runs,
        routes_candidates,
        view_socket,
    ):
        app.include_router(module.router)

    @app.get("/", include_in_schema=False)
    async def index():
        page = STATIC_DIR / "index.html"
        if page.is_file():
            return FileResponse(page, media_type="text/html")
        return HTMLResponse(
            "<!doctype html><title>intuitf</title><h1>intuitf</h1>"
            "<p>The page's files are missing from this install; the API's schema is at "
            "/openapi.json.</p>"
        )

    @app.get("/static/{path:path}", include_in_schema=False)
    async def static(path: str):
        root = STATIC_DIR.resolve()
        try:
            target = (root / path).resolve()
            found = target.is_file() and root in target.parents
        except (ValueError, OSError):  # a NUL byte, a name too long: no file of the page
            found = False
        if not found:
            raise ApiError(404, "No such file.")
        media = {".js": "text/javascript", ".mjs": "text/javascript", ".css": "text/css",
                 ".svg": "image/svg+xml", ".html": "text/html", ".json": "application/json",
                 ".png": "image/png", ".woff2": "font/woff2"}.get(target.suffix)  # fmt: skip
        return FileResponse(target, media_type=media)

    app.add_middleware(
        SecurityMiddleware,
        token=token,
        allowed_hosts=list(allowed_hosts) if allowed_hosts else list(DEFAULT_HOSTS),
        max_body_bytes=int(max_upload_bytes) + 1024 * 1024,
        upload_limit=int(max_upload_bytes),
    )
    return app


def make_server(app: FastAPI, host: str = "127.0.0.1", port: int = 8000, **config):
    """A ``uvicorn.Server`` for ``app`` whose Ctrl-C ends event streams and cancels runs at
    once (an open event stream would otherwise hold the server up until it closes)."""
    import uvicorn

    web: WebState = app.state.web

    class _Server(uvicorn.Server):
        def handle_exit(self, sig, frame) -> None:
            web.begin_shutdown()
            super().handle_exit(sig, frame)

    config.setdefault("log_level", "warning")
    config.setdefault("ws", "auto")
    config.setdefault("timeout_graceful_shutdown", 5)
    return _Server(uvicorn.Config(app, host=host, port=port, lifespan="on", **config))
