"""The runs a server drives (the web app, the MCP server): name → live session, each on a
thread of its own.

A live run's session runs ``arun()`` on its own thread and event loop, so nothing a run does
(a metric judge's arithmetic, writing its journal and pictures) ever holds up the server's
event loop: pages, event streams and view frames stay responsive while runs go. Everything
that changes a live session (a person's verdict, a query, pause, cancel) is handed to that
loop and runs there between the session's own steps, never beside them; a query waits for
the generation in progress to end (:class:`LiveSession`). When a run ends its session is
closed (the run folder's lock released); the next change to it reopens it with
:meth:`Session.resume`.
"""

from __future__ import annotations

import asyncio
import logging
import os
import threading
import time
from collections.abc import Callable
from typing import Any

from intuitf.errors import RunBusy, TooManyRuns
from intuitf.session.events import RunEvent
from intuitf.session.records import GenerationRecord, RunOutcome
from intuitf.session.scheduler import BATCH, render_scheduler
from intuitf.session.session import Session

log = logging.getLogger(__name__)


class LiveSession(Session):
    """A Session that can be told to start a new query at its next generation boundary."""

    _deferred: list[Callable[[], None]] | None = None
    _in_step: bool = False

    @property
    def stepping(self) -> bool:
        return self._in_step

    def at_boundary(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` now if no generation is in progress, else when the current one ends."""
        if not self._in_step:
            fn()
            return
        if self._deferred is None:
            self._deferred = []
        self._deferred.append(fn)

    def has_deferred(self) -> bool:
        return bool(self._deferred)

    def run_deferred(self) -> None:
        work, self._deferred = self._deferred or [], None
        for fn in work:
            try:
                fn()
            except Exception as exc:  # a query that fails later is reported, not raised
                log.warning("deferred change to %s failed: %s", self.name, exc)

    async def astep(self) -> GenerationRecord:
        self.run_deferred()
        self._in_step = True
        try:
            return await super().astep()
        finally:
            self._in_step = False


class Progress:
    """Counts from a run's events: matches of the generation, calls, money, time left."""

    def __init__(self, session: Session) -> None:
        self.session = session
        self.matches_done = 0
        self.matches_total = 0
        self.seconds: list[float] = []
        self.last_error: str | None = None

    def __call__(self, e: RunEvent) -> None:
        from intuitf.evaluator.tournament import default_rounds

        d = e.data
        if e.type == "generation_started":
            n = int(d.get("population", 0))
            self.matches_done = 0
            self.matches_total = default_rounds(n) * (n // 2)
        elif e.type == "match_judged":
            self.matches_done += 1
            if d.get("error"):
                self.last_error = str(d["error"])
        elif e.type == "generation_ended":
            self.seconds.append(float(d.get("seconds", 0.0)))

    def to_dict(self) -> dict[str, Any]:
        snap = self.session.snapshot()
        left = None
        if self.seconds:
            per = sum(self.seconds[-3:]) / len(self.seconds[-3:])
            left = round(per * max(0, snap.generations - snap.generation), 1)
        return {
            "stage": snap.stage,
            "generation": snap.generation,
            "generations": snap.generations,
            "matches_done": self.matches_done,
            "matches_total": self.matches_total,
            "calls": snap.cost.calls,
            "usd": snap.cost.usd,
            "seconds_left": left,
            "status": snap.status,
            "last_error": self.last_error,
        }


class LiveRun:
    """One session driven on its own thread until its run ends, then closed."""

    def __init__(self, name: str, session: LiveSession, on_closed: Callable[[LiveRun], None]):
        self.name = name
        self.session = session
        self.progress = Progress(session)
        self._unsubscribe = session.events.subscribe(self.progress)
        self._on_closed = on_closed
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self.loop: asyncio.AbstractEventLoop | None = None
        self.thread: threading.Thread | None = None
        self.state = "starting"  # starting | running | closing | closed
        self._calls = 0  # changes handed to the run's loop and not yet done
        self.outcome: RunOutcome | None = None
        self.started = time.time()
        self._closed_waiters: list[tuple[asyncio.AbstractEventLoop, asyncio.Future]] = []

    # -- the run's thread ------------------------------------------------------------------
    def start(self) -> None:
        self.state = "running"
        self.thread = threading.Thread(target=self._main, name=f"intuitf-run-{self.name}",
                                       daemon=True)  # fmt: skip
        self.thread.start()
        self._ready.wait()

    def _main(self) -> None:
        _lower_priority()
        loop = asyncio.new_event_loop()
        self.loop = loop
        self._ready.set()
        try:
            loop.run_until_complete(self._drive())
        except BaseException as exc:  # pragma: no cover - never expected; logged, not lost
            log.exception("run %s stopped unexpectedly: %s", self.name, exc)
        finally:
            try:
                loop.run_until_complete(loop.shutdown_asyncgens())
            finally:
                loop.close()
            self._unsubscribe()
            with self._lock:
                self.state = "closed"
                waiters, self._closed_waiters = self._closed_waiters, []
            for wloop, fut in waiters:
                wloop.call_soon_threadsafe(_resolve, fut)
            self._on_closed(self)

    async def _drive(self) -> None:
        s = self.session
        try:
            while True:
                try:
                    outcome = self.outcome = await s.arun(write_outputs=False)
                except Exception as exc:  # a bug, not a run condition: say so, then close
                    log.exception("run %s failed", self.name)
                    # The event first: once the run is no longer live, a status read looks
                    # for how it ended, and must not find a run cut off by a crash.
                    s.events.emit("run_ended", reason="error", message=f"The run failed: {exc}",
                                  generation=s.generation)  # fmt: skip
                    with self._lock:
                        self.state = "closing"
                    return
                # Changes handed over while the run ended are applied before deciding: a
                # query made meanwhile (or during the last generation) extends the run.
                while True:
                    with self._lock:
                        if self._calls == 0:
                            s.run_deferred()
                            go_on = outcome.reason == "completed" and not s.done
                            if not go_on:
                                self.state = "closing"
                            break
                    await asyncio.sleep(0.005)
                if not go_on:
                    break
            if s.run_dir is not None and s.last_ranking:
                # Best pictures, exports and the report: rendered behind interactive views.
                try:
                    await render_scheduler().run(s.write_outputs, BATCH)
                except Exception as exc:
                    log.warning("writing the outputs of %s failed: %s", self.name, exc)
        finally:
            await s.aclose()

    # -- from the server's loop ------------------------------------------------------------
    @property
    def live(self) -> bool:
        return self.state == "running"

    async def call(self, fn: Callable[[], Any]) -> Any:
        """Run ``fn`` on the run's loop (between the session's own steps) and return its result.

        Raises :class:`NotLive` when the run has begun closing.
        """
        with self._lock:
            if self.state != "running" or self.loop is None:
                raise NotLive(self.name)
            self._calls += 1

            async def job() -> Any:
                try:
                    return fn()
                finally:
                    with self._lock:
                        self._calls -= 1

            fut = asyncio.run_coroutine_threadsafe(job(), self.loop)
        return await asyncio.wrap_future(fut)

    async def wait_closed(self, timeout: float | None = None) -> bool:
        loop = asyncio.get_running_loop()
        with self._lock:
            if self.state == "closed":
                return True
            fut = loop.create_future()
            self._closed_waiters.append((loop, fut))
        try:
            await asyncio.wait_for(asyncio.shield(fut), timeout)
            return True
        except TimeoutError:
            return False


def _lower_priority(niceness: int = 10) -> None:
    """Let this thread (a run's judging and bookkeeping) yield the CPU to the server's own
    threads, so that views stay responsive while runs go (Linux: per-thread nice value)."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), niceness)
    except (AttributeError, OSError):  # other systems: the run just shares the CPU evenly
        pass


class NotLive(Exception):
    """The run is not (or no longer) driven by this server."""


def _resolve(fut: asyncio.Future) -> None:
    if not fut.done():
        fut.set_result(None)


class RunRegistry:
    """Live runs by name, and a signal for whoever waits for a run to start or stop."""

    def __init__(self, max_live: int = 4) -> None:
        self.max_live = max_live
        self._runs: dict[str, LiveRun] = {}
        self._lock = threading.Lock()
        self._changed: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    def bind(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._changed = asyncio.Event()

    def changed_event(self) -> asyncio.Event:
        if self._changed is None:
            self.bind(asyncio.get_running_loop())
        assert self._changed is not None
        return self._changed

    def _notify(self) -> None:
        def fire() -> None:
            old, self._changed = self._changed, asyncio.Event()
            if old is not None:
                old.set()

        if self._loop is not None and not self._loop.is_closed():
            try:
                self._loop.call_soon_threadsafe(fire)
            except RuntimeError:
                pass

    def get(self, name: str) -> LiveRun | None:
        """The live run ``name`` (None once it began closing)."""
        run = self._runs.get(name)
        return run if run is not None and run.live else None

    def entry(self, name: str) -> LiveRun | None:
        """The run ``name`` even while it closes (to wait for it)."""
        return self._runs.get(name)

    def names(self) -> list[str]:
        return [n for n, r in self._runs.items() if r.live]

    def check_capacity(self) -> None:
        if len(self.names()) >= self.max_live:
            going = "1 run is" if self.max_live == 1 else f"{self.max_live} runs are"
            raise TooManyRuns(
                f"{going} going already (the most this server drives at once).",
                "Wait for one to finish, or pause or stop one.",
            )

    def start(self, session: LiveSession) -> LiveRun:
        """Drive ``session`` on its own thread (call from the server's loop)."""
        if self._loop is None:
            self.bind(asyncio.get_running_loop())
        name = session.name
        with self._lock:
            old = self._runs.get(name)
            if old is not None and old.state in ("running", "starting"):
                raise RunBusy(f"The run {name!r} is going already.")
            run = LiveRun(name, session, self._closed)
            self._runs[name] = run
        run.start()
        self._notify()
        return run

    def _closed(self, run: LiveRun) -> None:
        with self._lock:
            if self._runs.get(run.name) is run:
                del self._runs[run.name]
        self._notify()

    async def wait_released(self, name: str, timeout: float = 30.0) -> None:
        """Wait until run ``name`` (if it is closing) has released its folder."""
        run = self._runs.get(name)
        if run is not None and not run.live:
            await run.wait_closed(timeout)

    async def close_all(self, timeout: float = 20.0) -> None:
        """Cancel every live run (between matches) and wait for each to close."""
        runs = list(self._runs.values())
        for run in runs:
            try:  # on the run's loop, so that it cannot fall between two generations
                await asyncio.wait_for(run.call(run.session.cancel), 5.0)
            except (NotLive, TimeoutError):
                pass
        for run in runs:
            if not await run.wait_closed(timeout):
                log.warning("run %s did not stop within %.0f s", run.name, timeout)
