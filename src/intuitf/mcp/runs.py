"""Runs for agents: start, follow, steer, judge, pick, refine, branch.

Every run is a :class:`~intuitf.session.Session` in a folder under ``--runs``, driven by the
web app's :class:`~intuitf.session.live.RunRegistry`: its own thread and event loop, changes handed
to it between matches, closed (folder lock released) when it ends and reopened with
:meth:`Session.resume` when changed again. Tools return at once; :meth:`RunDesk.wait` waits for
the next generation without holding up anything else.
"""

from __future__ import annotations

import asyncio
import threading
from functools import partial
from typing import TYPE_CHECKING, Any

from intuitf.errors import IntuitfError, SessionError
from intuitf.session.scheduler import INTERACTIVE, render_scheduler

if TYPE_CHECKING:
    from intuitf.mcp.service import McpService, Reply

#: The longest a wait may last (seconds): MCP clients time tool calls out.
MAX_WAIT = 300.0
#: Longest text of a judge's reason kept in results.
REASON_CHARS = 300


def _reply(data: dict, pictures=()) -> Reply:
    from intuitf.mcp.service import Reply

    return Reply(data, list(pictures))


class RunDesk:
    """Run operations of :class:`~intuitf.mcp.service.McpService`."""

    def __init__(self, service: McpService) -> None:
        self.svc = service
        self._create_lock = threading.Lock()
        #: Features an agent selected, per candidate (run-qualified id -> Gaussian indices).
        self.selections: dict[str, list[int]] = {}

    @property
    def store(self):
        return self.svc.store

    @property
    def registry(self):
        return self.svc.registry

    # -- lookups --------------------------------------------------------------------------
    def check_run(self, name: Any) -> str:
        """``name`` if it is a run under ``--runs`` (SessionError otherwise)."""
        from intuitf.session import RunDirectory

        if not isinstance(name, str):
            raise SessionError("A run is named by its name (a string), as start_run returns it.")
        path = self.store.path_of(name)
        self.svc.roots.run_folder(path)
        if not RunDirectory(path).run_json.is_file():
            raise SessionError(
                f"There is no run {name[:80]!r} in {self.store.root}.",
                "Use a name from list_runs (or the one start_run returned).",
            )
        return name

    def record(self, name: str) -> dict:
        from intuitf.session import RunDirectory

        return RunDirectory(self.store.path_of(self.check_run(name))).read_run()

    def volume_of(self, name: str):
        """The open volume of run ``name`` (opened if need be) and the run's settings."""
        from intuitf.session.building import spec_of_record

        record = self.record(name)
        spec = spec_of_record(record)
        if not spec.volume.source:
            raise SessionError(
                f"Run {name!r} was made from a volume in memory; its source is unknown.",
                "Open the volume yourself and render its TF with get_tf / render.",
            )
        return self.svc.shelf.for_spec(spec.volume), dict(record.get("settings") or {})

    def _live(self, name: str):
        return self.registry.get(name)

    # -- building specs -------------------------------------------------------------------
    def intent_data(self, intent: Any) -> dict[str, Any]:
        """Spec data of an intent an agent gave: words, or an object whose pictures are paths
        (checked against the roots)."""
        if intent is None:
            return {}
        if isinstance(intent, str):
            if not intent.strip():
                raise SessionError("The intent text is empty.", "Say what the picture should show.")
            return {"kind": "text", "text": intent}
        if not isinstance(intent, dict):
            raise SessionError(
                f"An intent is text or an object, got {type(intent).__name__}.",
                '{"kind": "image", "reference": "path.png"} or {"kind": "text", "text": "..."}',
            )
        data = dict(intent)
        if "kind" not in data:
            data["kind"] = next(
                (k for k, f in (("sketch", "sketch"), ("image", "reference"), ("text", "text"))
                 if data.get(f)), "none",
            )  # fmt: skip
        for name in ("reference", "sketch", "base"):
            if data.get(name):
                data[name] = str(self.svc.roots.readable(data[name], f"{name} picture"))
        return data

    def judge_data(self, judge: Any, budget_usd=None, budget_calls=None) -> dict[str, Any]:
        cfg = self.svc.config
        if judge is None:
            data: dict[str, Any] = {"spec": cfg.evaluator}
        elif isinstance(judge, str):
            data = {"spec": judge}
        elif isinstance(judge, dict):
            data = dict(judge)
        else:
            raise SessionError(
                "A judge is a spec string (metric, openai:MODEL, a URL) or an object."
            )
        if budget_usd is not None:
            data["budget_usd"] = budget_usd
        if budget_calls is not None:
            data["budget_calls"] = budget_calls
        # The server's budgets apply to every model judge that brings none of its own.
        if data.get("spec", "metric") != "metric":
            if data.get("budget_usd") is None and cfg.budget_usd is not None:
                data["budget_usd"] = cfg.budget_usd
            if data.get("budget_calls") is None and cfg.budget_calls is not None:
                data["budget_calls"] = cfg.budget_calls
        return data

    # -- starting -------------------------------------------------------------------------
    async def start(
        self,
        *,
        volume_id: str,
        intent: Any,
        judge: Any,
        budget_usd: float | None,
        budget_calls: int | None,
        settings: dict[str, Any] | None,
        start_from_tf: bool,
        name: str | None,
    ) -> Reply:
        from intuitf.session.live import LiveSession
        from intuitf.session.spec import parse_spec

        svc = self.svc
        ov = svc.shelf.get(volume_id)
        vol = await asyncio.to_thread(svc.shelf.volume, ov)
        data = {
            "volume": ov.spec.model_dump(exclude_none=True),
            "intent": self.intent_data(intent),
            "judge": self.judge_data(judge, budget_usd, budget_calls),
            "settings": dict(settings or {}),
            "initial": [svc.shelf.current_tf(ov).to_dict()] if start_from_tf else [],
        }
        if name is not None and not isinstance(name, str):
            raise SessionError("A run name is text.")
        spec = parse_spec(data)
        self.registry.check_capacity()

        def make():
            with self._create_lock:  # a name no other start takes meanwhile
                run_name = self.store.new_name(name or ov.id)
                folder = svc.roots.run_folder(self.store.path_of(run_name))
                return LiveSession.open(
                    spec.model_copy(update={"name": run_name}), folder, volume=vol
                )

        session = await asyncio.to_thread(make)
        await self._start(session)
        snap = session.snapshot()
        return _reply(
            {
                "run": session.name,
                "status": "running",
                "volume": ov.id,
                "judge": session.judge_name,
                "plan": [list(p) for p in snap.plan],
                "population": session.settings.population,
                "path": str(session.run_dir.root) if session.run_dir else None,
                # How the words were read on the volume: check before waiting on results.
                "understood": list(session.understood),
                "next": "Follow it with run_status or wait_for_generation; see results with gallery.",
            }
        )

    async def _start(self, session) -> None:
        try:
            self.registry.check_capacity()
            self.registry.start(session)
        except BaseException:
            await session.aclose()
            raise

    async def _reopen(self, name: str, *, for_verdict: bool = False, **kw):
        from intuitf.session.live import LiveSession

        await self.registry.wait_released(name)
        record = await asyncio.to_thread(self.record, name)
        if record.get("kind") == "edit":
            raise SessionError(f"{name!r} is a hand edit, not a run.", "Branch or refine from it.")
        ov, _ = await asyncio.to_thread(self.volume_of, name)
        vol = await asyncio.to_thread(self.svc.shelf.volume, ov)
        judge = None
        if for_verdict:  # a verdict asks no model: no key or server needed to record it
            from intuitf.evaluator.metric import MetricJudge

            judge = MetricJudge()
        return await asyncio.to_thread(
            LiveSession.resume, self.store.path_of(name), vol, judge, **kw
        )

    # -- following ------------------------------------------------------------------------
    def list_runs(self) -> Reply:
        runs = []
        for info in self.store.runs():
            d = info.to_dict()
            d["live"] = self._live(info.name) is not None
            runs.append(d)
        return _reply({"runs": runs, "root": str(self.store.root)})

    def status(self, name: str, since: int = 0, limit: int = 50, matches: bool = False) -> Reply:
        from intuitf.session import RunDirectory
        from intuitf.session.events import read_events

        self.check_run(name)
        info = self.store.run(name)
        live = self._live(name)
        closing = live is None and self.registry.entry(name) is not None
        if live is not None:
            progress = live.progress.to_dict()
            events = live.session.events.since(int(since))
        else:
            cost = info.cost or {}
            progress = {
                "stage": None, "generation": info.generations_done,
                "generations": info.generations, "calls": cost.get("calls", 0),
                "usd": cost.get("usd", 0.0), "status": info.status,
            }  # fmt: skip
            events = [e for e in read_events(RunDirectory(info.path).events) if e.seq > int(since)]
        limit = max(1, min(int(limit), 500))
        # Each match's verdict is the bulk of a run's events: only when asked for.
        kept = [e for e in events if matches or e.type != "match_judged"]
        shown = kept[:limit]
        if len(kept) > limit:
            next_since = shown[-1].seq
        else:
            next_since = events[-1].seq if events else int(since)
        return _reply(
            {
                "run": name,
                "live": live is not None,
                "status": "finishing" if closing else progress.get("status", info.status),
                "progress": progress,
                "info": _info(info),
                "events": [_event(e) for e in shown],
                "next_since": next_since,
                "more_events": len(kept) > len(shown),
            }
        )

    async def wait(
        self, name: str, timeout_s: float, since: int | None, matches: bool = False
    ) -> Reply:
        """Wait until a generation after ``since`` (default: now) ends, or the run ends."""
        self.check_run(name)
        timeout = max(0.0, min(float(timeout_s), MAX_WAIT))
        live = self._live(name)
        outcome = "not_running"
        ended = []
        if live is not None:
            events = live.session.events
            start = events.last_seq if since is None else int(since)
            loop = asyncio.get_running_loop()
            done = asyncio.Event()

            def on_event(e) -> None:
                if e.seq > start and e.type in ("generation_ended", "run_ended"):
                    if e.type == "run_ended":
                        ended.append(True)
                    loop.call_soon_threadsafe(done.set)

            unsubscribe = events.subscribe(on_event, since=start)
            try:
                await asyncio.wait_for(done.wait(), timeout)
                outcome = "generation_ended"
            except TimeoutError:
                outcome = "timeout"
            finally:
                unsubscribe()
            since_out = start
        else:
            since_out = int(since or 0)
        # A run that ended is still writing its outputs until it releases its folder.
        entry = self.registry.entry(name)
        if entry is not None and (live is None or ended or not entry.live):
            await entry.wait_closed(max(timeout, 5.0))
        reply = await asyncio.to_thread(self.status, name, since_out, 50, matches)
        ended = [e for e in reply.data["events"] if e["type"] == "run_ended"]
        if ended:
            outcome = "run_ended"
        reply.data["outcome"] = outcome
        return reply

    # -- control --------------------------------------------------------------------------
    async def control(self, name: str, action: str) -> Reply:
        from intuitf.session.live import NotLive

        self.check_run(name)
        live = self._live(name)
        if live is None:
            raise SessionError(
                f"The run {name!r} is not going.",
                "continue_run starts it again" if action != "cancel" else "Nothing to cancel.",
            )
        s = live.session
        try:
            await live.call(getattr(s, action))
        except NotLive:
            raise SessionError(f"The run {name!r} has ended.") from None
        status = "cancelling" if action == "cancel" else s.snapshot().status
        return _reply({"run": name, "status": status, "paused": action == "pause"})

    async def continue_run(self, name, budget_usd, budget_calls, judge: str | None) -> Reply:
        from intuitf.session.live import NotLive

        self.check_run(name)
        live = self._live(name)
        if live is not None:
            try:
                await live.call(live.session.proceed)
            except NotLive:
                live = None
            else:
                return _reply({"run": name, "status": "running", "resumed": False})
        self.registry.check_capacity()
        session = await self._reopen(
            name, budget_usd=budget_usd, budget_calls=budget_calls, evaluator=judge
        )
        if session.done:
            await session.aclose()
            raise SessionError(
                f"The run {name!r} has done all its generations.",
                "Ask a new query to go on with it (new_query), or branch from it.",
            )
        await self._start(session)
        return _reply({"run": name, "status": "running", "resumed": True,
                       "generation": session.generation})  # fmt: skip

    # -- the gallery ----------------------------------------------------------------------
    async def gallery(self, name: str, k: int, size: int, pictures: bool) -> Reply:
        from intuitf.session.live import NotLive

        self.check_run(name)
        k = max(1, min(int(k), 16))
        live = self._live(name)
        best: list[tuple[str, float | None]] | None = None
        if live is not None:
            s = live.session
            try:
                got = await live.call(lambda: s.best_candidates(k))
                best = [(cid, float(r)) for cid, _tf, r in got]
            except NotLive:
                best = None
        if best is None:
            best = await asyncio.to_thread(_best_from_folder, self.store, name, k)
        reasons, generation = await asyncio.to_thread(_reasons, self.store, name)
        items = []
        for rank, (cid, rating) in enumerate(best, start=1):
            qid = f"{name}/{cid}"
            info = await asyncio.to_thread(self.store.candidate, qid)
            items.append(
                {
                    "id": qid,
                    "rank": rank,
                    "rating": None if rating is None else round(float(rating), 1),
                    "generation": info.generation,
                    "origin": info.origin,
                    "gaussians": len(info.tf),
                    "judge": reasons.get(cid, []),
                    "selected": self.selections.get(qid, []),
                }
            )
        data: dict[str, Any] = {"run": name, "generation": generation, "candidates": items}
        pics = []
        if pictures and items:
            pics = await self._sheet(name, items, size)
            data["picture"] = str(pics[0].path)
            data["pictures"] = [str(p.path) for p in pics[1:]]
        return _reply(data, pics[:1])

    async def _sheet(self, name: str, items: list[dict], size: int):
        from intuitf.mcp.service import Picture, check_background, check_size
        from intuitf.plots import contact_sheet

        size = check_size(size)
        ov, settings = await asyncio.to_thread(self.volume_of, name)
        vol = await asyncio.to_thread(self.svc.shelf.volume, ov)
        cam = self.svc._camera(None, settings, vol)
        shaded = bool(settings.get("shading", True))
        bg = check_background(None, settings)
        vr = await asyncio.to_thread(self.svc.shelf.view_renderer, ov, bg)
        images, out = [], []
        # One camera for all: the volume is sampled once, each candidate is a LUT pass.
        cache = await render_scheduler().run(
            partial(vr.sample_cache, cam, size, shaded), INTERACTIVE
        )
        for item in items:
            tf = (await asyncio.to_thread(self.store.candidate, item["id"])).tf
            img = await render_scheduler().run(partial(cache.render, tf), INTERACTIVE)
            images.append(img)
            path = await asyncio.to_thread(
                self.svc.save_picture, img, item["id"].replace("/", "-"), cam, vol, shaded, bg
            )
            out.append(Picture(img, path, item["id"]))
        captions = [f"#{i['rank']} {i['id'].split('/')[1]} {i['rating'] or 0:.0f}" for i in items]
        sheet = contact_sheet(images, captions, columns=min(4, len(images)), thumb=min(size, 256))
        path = await asyncio.to_thread(
            self.svc.save_picture, sheet, f"{name}-gallery", cam, vol, shaded, bg
        )
        return [Picture(sheet, path, "gallery"), *out]

    # -- a person's (an agent's) verdicts ---------------------------------------------------
    async def human(self, name: str, fn) -> Reply:
        from intuitf.session.live import NotLive

        self.check_run(name)
        live = self._live(name)
        if live is not None:
            s = live.session
            try:
                v, ranking = await live.call(lambda: (fn(s), list(s.last_ranking)))
                return _reply({"run": name, "verdict": v.to_dict(), "ranking": ranking[:8]})
            except NotLive:
                pass
        session = await self._reopen(name, for_verdict=True)
        try:
            v = await asyncio.to_thread(fn, session)
            return _reply(
                {"run": name, "verdict": v.to_dict(), "ranking": list(session.last_ranking)[:8]}
            )
        finally:
            await session.aclose()

    # -- features -------------------------------------------------------------------------
    async def _candidate_view(self, candidate, camera, size, shaded, background):
        from intuitf.mcp.service import check_background, check_size

        info = await asyncio.to_thread(self.svc.candidate, candidate)
        ov, settings = await asyncio.to_thread(self.volume_of, info.run)
        vol = await asyncio.to_thread(self.svc.shelf.volume, ov)
        size = check_size(size)
        cam = self.svc._camera(camera, settings, vol)
        shaded = bool(settings.get("shading", True)) if shaded is None else bool(shaded)
        bg = check_background(background, settings)
        vr = await asyncio.to_thread(self.svc.shelf.view_renderer, ov, bg)
        return info, vol, vr, cam, size, shaded, bg

    async def select(
        self, candidate, *, x, y, index, camera, size, shaded, clear, whole=False
    ) -> Reply:
        """Select a feature of a candidate by picture coordinates (the paper's rule: of the
        features that make the pixel, the one with the smallest projected area; with
        ``whole``, all of them) or by index."""
        from intuitf.mcp.camera import describe as describe_camera
        from intuitf.mcp.pictures import outline, side_by_side
        from intuitf.mcp.service import Picture

        info, vol, vr, cam, size, shaded, bg = await self._candidate_view(
            candidate, camera, size, shaded, None
        )
        tf, qid = info.tf, info.qid
        if clear:
            self.selections.pop(qid, None)
        pick = None
        if index is not None:
            if not isinstance(index, int) or not 0 <= index < len(tf):
                raise SessionError(
                    f"Candidate {qid} has Gaussians 0 to {len(tf) - 1}; there is no {index!r}.",
                    "Pick by index from features, or by x and y on its picture.",
                )
            chosen: int | None = index
            picked: tuple[int, ...] = (index,)
        elif x is not None and y is not None:
            pick = await render_scheduler().run(
                lambda: vr.pick(tf, cam, int(x), int(y), size, shaded, whole=bool(whole)),
                INTERACTIVE,
            )
            chosen, picked = pick.index, pick.selected
        elif clear:
            return _reply({"candidate": qid, "selected": []})
        else:
            raise SessionError(
                "Say which feature: x and y on the candidate's picture, or its index.",
                "x, y are pixels from the top-left of a picture of the given size.",
            )
        data: dict[str, Any] = {
            "candidate": qid,
            "chosen": chosen,
            "camera": describe_camera(cam, vol.extent),
            "size": size,
        }
        if pick is not None:
            data["at"] = [int(x), int(y)]
            data["visible_here"] = [
                {"index": i, "share": round(share, 3), "area_pixels": area}
                for i, share, area in pick.visible
            ]
        if chosen is None:
            data["selected"] = self.selections.get(qid, [])
            data["message"] = "Nothing visible at that pixel: no feature selected."
            return _reply(data)
        sel = sorted({*self.selections.get(qid, []), *(int(i) for i in picked)})
        self.selections[qid] = sel
        data["selected"] = sel
        if len(picked) > 1:
            data["picked"] = list(picked)
            data["gaussians"] = [tf.gaussians[i].to_dict() for i in picked]
        else:
            data["gaussian"] = tf.gaussians[chosen].to_dict()

        def pictures():
            cache = vr.sample_cache(cam, size, shaded)  # the pick's, when there was one
            view = cache.render(tf)
            if pick is not None and pick.mask is not None:
                view = outline(view, pick.mask)
            alone = cache.render_feature(tf, list(picked))
            return side_by_side([view, alone])

        image = await render_scheduler().run(pictures, INTERACTIVE)
        name = "-".join(str(i) for i in picked)
        path = await asyncio.to_thread(
            self.svc.save_picture, image, f"{qid.replace('/', '-')}-feature{name}",
            cam, vol, shaded, bg,
        )  # fmt: skip
        data["path"] = str(path)
        data["picture"] = (
            "left: the candidate with the picked feature(s) outlined; right: they alone"
        )
        return _reply(data, [Picture(image, path)])

    async def features(self, candidate, *, camera, size, shaded) -> Reply:
        """Each Gaussian of a candidate rendered alone, in TF order (select by index)."""
        from intuitf.mcp.camera import describe as describe_camera
        from intuitf.mcp.service import Picture
        from intuitf.plots import contact_sheet

        info, vol, vr, cam, size, shaded, bg = await self._candidate_view(
            candidate, camera, size, shaded, None
        )
        tf = info.tf
        images = await render_scheduler().run(
            lambda: vr.features(tf, cam, size, shaded), INTERACTIVE
        )
        captions = [f"{i}: at {g.mean:.2f} h {g.height:.2f}" for i, g in enumerate(tf.gaussians)]
        sheet = contact_sheet(images, captions, columns=min(4, len(images)), thumb=min(size, 192))
        path = await asyncio.to_thread(
            self.svc.save_picture, sheet, f"{info.qid.replace('/', '-')}-features",
            cam, vol, shaded, bg,
        )  # fmt: skip
        data = {
            "candidate": info.qid,
            "features": [
                {"index": i, **g.to_dict(), "value": round(float(vol.to_original(g.mean)), 4)}
                for i, g in enumerate(tf.gaussians)
            ],  # fmt: skip
            "selected": self.selections.get(info.qid, []),
            "camera": describe_camera(cam, vol.extent),
            "path": str(path),
        }
        return _reply(data, [Picture(sheet, path)])

    # -- new work from a run --------------------------------------------------------------
    async def refine(self, candidate, text, selected, generations, judge) -> Reply:
        info = await asyncio.to_thread(self.svc.candidate, candidate)
        sel = list(selected) if selected else list(self.selections.get(info.qid, []))
        if not sel:
            raise SessionError(
                f"No feature of {info.qid} is selected.",
                "Select one with select_feature (x, y or index), or pass selected=[indices].",
            )
        bad = [i for i in sel if not isinstance(i, int) or not 0 <= i < len(info.tf)]
        if bad:
            raise SessionError(
                f"Candidate {info.qid} has Gaussians 0 to {len(info.tf) - 1}; {bad} are not among them."
            )
        if not isinstance(text, str) or not text.strip():
            raise SessionError("Say in words how the selected features should change.")
        record = await asyncio.to_thread(self.record, info.run)
        about = ((record.get("spec") or {}).get("intent") or {}).get("about")
        n = int(generations or (record.get("settings") or {}).get("generations", 4))
        changes: dict[str, Any] = {
            "intent": {"kind": "edit", "text": text, "selected": sorted(sel), "about": about},
            "settings": {"generations": n, "stages": [["refine", n]]},
        }
        if judge is not None:
            changes["judge"] = self.judge_data(judge)
        name = await self._branch(info.run, f"{info.run}-refine", None, info.id, changes)
        return _reply({"run": name, "status": "running", "from": info.qid, "selected": sorted(sel),
                       "text": text, "generations": n})  # fmt: skip

    async def query(self, name: str, intent: Any, generations: int | None) -> Reply:
        from intuitf.session.building import load_intent
        from intuitf.session.live import NotLive
        from intuitf.session.spec import IntentSpec

        self.check_run(name)
        data = self.intent_data(intent)
        if not data or data.get("kind") in (None, "none"):
            raise SessionError("A new query needs an intent: words, a reference or a sketch.")
        if data.get("kind") == "edit":
            raise SessionError("To change selected features, use refine.")

        def build():
            try:
                return load_intent(IntentSpec.model_validate(data))
            except ValueError as exc:
                raise SessionError(f"The intent is not valid: {_short(exc)}.") from None

        new_intent = await asyncio.to_thread(build)
        gens = int(generations) if generations else None
        live = self._live(name)
        if live is not None:
            s = live.session
            try:
                deferred = await live.call(
                    lambda: (s.at_boundary(lambda: s.query(new_intent, gens)), s.has_deferred())[1]
                )
                said = {} if deferred else {"understood": list(s.understood)}
                return _reply({"run": name, "status": "running", "applied": not deferred, **said,
                               "note": "starts after the generation in progress" if deferred else ""})  # fmt: skip
            except NotLive:
                pass
        self.registry.check_capacity()
        session = await self._reopen(name)
        try:
            await asyncio.to_thread(session.query, new_intent, gens)
        except BaseException:
            await session.aclose()
            raise
        await self._start(session)
        return _reply({"run": name, "status": "running", "applied": True,
                       "understood": list(session.understood)})  # fmt: skip

    async def branch(self, name, generation, candidate, changes) -> Reply:
        self.check_run(name)
        cid = None
        if candidate is not None:
            qid = candidate if "/" in str(candidate) else f"{name}/{candidate}"
            info = await asyncio.to_thread(self.svc.candidate, qid)
            if info.run != name:
                raise SessionError(f"{qid} is not a candidate of run {name!r}.")
            cid = info.id
        changes = dict(changes or {})
        allowed = {"intent", "judge", "settings"}
        bad = sorted(set(changes) - allowed)
        if bad:
            raise SessionError(
                f"A branch may change {sorted(allowed)}, not {bad}.",
                "Start a new run (start_run) for another volume.",
            )
        if "intent" in changes:
            changes["intent"] = self.intent_data(changes["intent"])
        if "judge" in changes:
            changes["judge"] = self.judge_data(changes["judge"])
        new = await self._branch(name, f"{name}-branch", generation, cid, changes)
        return _reply({"run": new, "status": "running", "from": name, "generation": generation,
                       "candidate": cid})  # fmt: skip

    async def _branch(self, name, base_name, generation, cid, changes) -> str:
        from intuitf.session.live import LiveSession

        self.registry.check_capacity()
        ov, _ = await asyncio.to_thread(self.volume_of, name)
        vol = await asyncio.to_thread(self.svc.shelf.volume, ov)
        parent_dir = self.store.path_of(name)

        def make():
            with self._create_lock:
                new = self.store.new_name(base_name)
                folder = self.svc.roots.run_folder(self.store.path_of(new))
                return LiveSession.branch(
                    parent_dir, folder, generation=generation, candidate=cid,
                    changes={**changes, "name": new}, volume=vol,
                )  # fmt: skip

        session = await asyncio.to_thread(make)
        await self._start(session)
        return session.name


# -- helpers ------------------------------------------------------------------------------------
def _short(exc: Exception) -> str:
    return str(exc).splitlines()[0][:300]


def _info(info) -> dict:
    d = info.to_dict()
    return {k: d[k] for k in ("name", "status", "generations_done", "generations", "cost",
                              "created", "volume", "intent", "judge", "parent", "message",
                              "path")}  # fmt: skip


def _event(e) -> dict:
    """An event, with the bulky parts (every candidate's rating) cut to what an agent reads."""
    d = dict(e.data)
    if e.type == "generation_ended":
        d = {
            "generation": d.get("generation"),
            "stage": d.get("stage"),
            "best": d.get("best"),
            "top": list(d.get("ranking", []))[:5],
            "seconds": round(float(d.get("seconds", 0.0)), 2),
            "calls": (d.get("cost") or {}).get("calls"),
            "usd": (d.get("cost") or {}).get("usd"),
            "match_stats": d.get("match_stats"),
        }
    elif e.type == "match_judged":
        d = {
            "generation": d.get("generation"),
            "round": d.get("round"),
            "first": d.get("first"),
            "second": d.get("second"),
            "winner": d.get("winner"),
            "reasons": {k: str(v)[:REASON_CHARS] for k, v in (d.get("reasons") or {}).items()},
            "error": d.get("error"),
        }
    elif e.type == "human_verdict":
        d = {"action": d.get("action"), "verdict": d.get("verdict"),
             "top": list(d.get("ranking", []))[:5]}  # fmt: skip
    return {"seq": e.seq, "type": e.type, "time": round(e.time, 3), "data": d}


def _best_from_folder(store, name: str, k: int) -> list[tuple[str, float | None]]:
    """The top ``k`` distinct candidates of a run that is not live (checkpoint or journal)."""
    from intuitf.session import RunDirectory

    rd = RunDirectory(store.path_of(name))
    try:
        ckpt = rd.read_checkpoint() or {}
    except IntuitfError:
        ckpt = {}
    ranking, ratings, tfs = ckpt.get("ranking", []), ckpt.get("ratings", {}), ckpt.get("tfs", {})
    if not ranking:
        gens = rd.generations()
        cands = (
            sorted(gens[-1].get("candidates", []), key=lambda c: c.get("rank", 0)) if gens else []
        )
        ranking = [c["id"] for c in cands]
        ratings = {c["id"]: c.get("rating") for c in cands}
        tfs = {c["id"]: c.get("tf") for c in cands}
    out, seen = [], set()
    for cid in ranking:
        key = repr(tfs.get(cid))
        if key in seen:
            continue
        seen.add(key)
        out.append((cid, ratings.get(cid)))
        if len(out) >= k:
            break
    return out


def _reasons(store, name: str, per_candidate: int = 3) -> tuple[dict[str, list[dict]], int | None]:
    """What the judge said about each candidate in the run's last judged generation."""
    from intuitf.session import RunDirectory

    gens = RunDirectory(store.path_of(name)).generations()
    if not gens:
        return {}, None
    last = gens[-1]
    out: dict[str, list[dict]] = {}
    for m in last.get("matches", []):
        v = m.get("verdict") or {}
        first, second = m.get("first"), m.get("second")
        overall = v.get("overall")
        reasons = {k: str(t)[:REASON_CHARS] for k, t in (v.get("rationale") or {}).items()}
        for me, other, mine in ((first, second, "first"), (second, first, "second")):
            if me is None:
                continue
            lst = out.setdefault(me, [])
            if len(lst) < per_candidate:
                won = None if overall not in ("first", "second") else overall == mine
                lst.append({"against": other, "won": won, "reasons": reasons})
    return out, int(last.get("generation", 0))
