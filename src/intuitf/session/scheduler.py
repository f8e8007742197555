"""One render scheduler per process: interactive renders go ahead of tournament batches.

The render kernels already use every core, so renders run one at a time on a single worker
thread; what matters is the order. Interactive work (a dragged view, a click to pick, the
feature decomposition) is queued at :data:`INTERACTIVE` priority and runs before any waiting
tournament render (:data:`BATCH`), so rotating a volume stays responsive while a run renders
its generation: a batch is submitted one candidate at a time, and an interactive frame waits
for at most one candidate's render.

Work runs on the worker thread and its result comes back as a ``concurrent.futures.Future``
(:meth:`RenderScheduler.submit`) or an awaitable (:meth:`RenderScheduler.run`).
"""

from __future__ import annotations

import asyncio
import itertools
import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, TypeVar

T = TypeVar("T")

INTERACTIVE = 0
BATCH = 10


class RenderScheduler:
    """A single render worker with a priority queue (lower number first, FIFO within one)."""

    def __init__(self) -> None:
        self._queue: queue.PriorityQueue[tuple[int, int, Future, Callable[[], Any]]] = (
            queue.PriorityQueue()
        )
        self._counter = itertools.count()
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._worker_id: int | None = None

    def submit(self, fn: Callable[[], T], priority: int = BATCH) -> Future[T]:
        """Queue ``fn`` and return a future for its result."""
        fut: Future[T] = Future()
        if threading.get_ident() == self._worker_id:
            # Called from a render itself: run inline instead of waiting on ourselves.
            _run_into(fut, fn)
            return fut
        self._ensure_worker()
        self._queue.put((priority, next(self._counter), fut, fn))
        return fut

    async def run(self, fn: Callable[[], T], priority: int = BATCH) -> T:
        """Await ``fn`` run on the render worker."""
        return await asyncio.wrap_future(self.submit(fn, priority))

    def call(self, fn: Callable[[], T], priority: int = BATCH) -> T:
        """Run ``fn`` on the render worker and wait for it (for synchronous callers)."""
        return self.submit(fn, priority).result()

    @property
    def pending(self) -> int:
        return self._queue.qsize()

    def _ensure_worker(self) -> None:
        with self._lock:
            if self._thread is None or not self._thread.is_alive():
                self._thread = threading.Thread(
                    target=self._work, name="intuitf-render", daemon=True
                )
                self._thread.start()

    def _work(self) -> None:
        self._worker_id = threading.get_ident()
        while True:
            _, _, fut, fn = self._queue.get()
            if fut.set_running_or_notify_cancel():
                _run_into(fut, fn)


def _run_into(fut: Future, fn: Callable[[], Any]) -> None:
    try:
        fut.set_result(fn())
    except BaseException as exc:  # handed to the waiting caller, never lost in the thread
        fut.set_exception(exc)


_scheduler: RenderScheduler | None = None
_scheduler_lock = threading.Lock()


def render_scheduler() -> RenderScheduler:
    """The process's render scheduler."""
    global _scheduler
    with _scheduler_lock:
        if _scheduler is None:
            _scheduler = RenderScheduler()
        return _scheduler
