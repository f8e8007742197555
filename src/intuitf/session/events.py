"""Typed, numbered run events, delivered to any number of subscribers and journaled.

Every event has a ``type``, a sequence number ``seq`` (1, 2, ... over the run's whole life,
across resumes), the run's name and a wall-clock time. The :class:`EventLog` appends each one to
the run folder's ``events.jsonl`` before handing it to subscribers, so a subscriber that
connects late (a reloaded web page, a restarted server) replays from a sequence number and
misses nothing.

Subscribers are plain callables (called in the thread that emits) or async iterators
(:meth:`EventLog.stream`), which are safe to consume from any event loop: events are passed
over with ``call_soon_threadsafe``.
"""

from __future__ import annotations

import asyncio
import json
import os
import threading
import time
from collections.abc import AsyncIterator, Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

#: The event types, in the order a run produces them.
EVENT_TYPES = (
    "run_started",  # a process started driving the run: spec summary, plan, judge
    "stage_started",  # stage name, generations, aspects
    "generation_started",  # generation, stage, population size
    "rendered",  # the generation's candidates are rendered
    "match_judged",  # both candidates, per-aspect verdict, the model's reasons, cost
    "generation_ended",  # the generation's record: ranking, ratings, cost, match statistics
    "human_verdict",  # a person's preference entered the tournament (or was undone)
    "query",  # a new intent starts a new customize stage
    "status",  # paused, resumed, cancelling
    "run_ended",  # reason and message
)


@dataclass(frozen=True)
class RunEvent:
    """One thing that happened in a run."""

    type: str
    seq: int
    run: str
    time: float
    data: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> RunEvent:
        return cls(
            type=str(d["type"]),
            seq=int(d["seq"]),
            run=str(d.get("run", "")),
            time=float(d.get("time", 0.0)),
            data=dict(d.get("data", {})),
        )


Subscriber = Callable[[RunEvent], None]


class EventLog:
    """The events of one run: numbered, journaled to ``path`` (if given), fanned out.

    Thread-safe: :meth:`emit` may be called from any thread; subscribers see events in
    sequence order, each exactly once.
    """

    def __init__(self, run: str, path: str | os.PathLike | None = None) -> None:
        self.run = run
        self.path = Path(path) if path is not None else None
        self._lock = threading.RLock()
        self._events: list[RunEvent] = list(read_events(self.path)) if self.path else []
        self._subscribers: list[Subscriber] = []
        #: The last event before this process took the run (earlier processes' events).
        self.opened_seq = self.last_seq

    @property
    def last_seq(self) -> int:
        return self._events[-1].seq if self._events else 0

    def emit(self, type: str, **data: Any) -> RunEvent:
        """Record an event of ``type`` with ``data`` (JSON-serialisable) and deliver it."""
        if type not in EVENT_TYPES:
            raise ValueError(f"Unknown event type {type!r}.")
        with self._lock:
            event = RunEvent(type, self.last_seq + 1, self.run, time.time(), _plain(data))
            if self.path is not None:
                self._append(event)
            self._events.append(event)
            subscribers = list(self._subscribers)
        for fn in subscribers:
            try:
                fn(event)
            except Exception:  # a broken display must never stop the run
                pass
        return event

    def since(self, seq: int = 0) -> list[RunEvent]:
        """Events with a sequence number above ``seq``, in order."""
        with self._lock:
            return [e for e in self._events if e.seq > seq]

    def subscribe(self, fn: Subscriber, since: int | None = None) -> Callable[[], None]:
        """Call ``fn`` for every new event, first replaying those after ``since``.

        Without ``since``, the replay holds the events this process emitted before the
        subscriber came (those of opening the run, such as its first ``stage_started``), so
        a subscriber that attaches after :meth:`Session.open` misses nothing of this
        session; ``since=0`` replays the run's whole history, earlier processes' included.
        Returns a function that unsubscribes. Replay and subscription happen under one lock,
        so no event is missed or seen twice.
        """
        with self._lock:
            backlog = self.since(self.opened_seq if since is None else since)
            self._subscribers.append(fn)
        for e in backlog:
            fn(e)

        def unsubscribe() -> None:
            with self._lock:
                if fn in self._subscribers:
                    self._subscribers.remove(fn)

        return unsubscribe

    async def stream(self, since: int = 0) -> AsyncIterator[RunEvent]:
        """Events after ``since`` and then every new one, as an async iterator (never ends)."""
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[RunEvent] = asyncio.Queue()

        def push(e: RunEvent) -> None:
            try:
                loop.call_soon_threadsafe(queue.put_nowait, e)
            except RuntimeError:  # the consumer's loop is closed
                pass

        unsubscribe = self.subscribe(push, since=since)
        try:
            while True:
                yield await queue.get()
        finally:
            unsubscribe()

    def _append(self, event: RunEvent) -> None:
        from intuitf.errors import StorageError

        assert self.path is not None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            with open(self.path, "a", encoding="utf-8") as fh:
                fh.write(json.dumps(event.to_dict(), separators=(",", ":")) + "\n")
        except OSError as exc:
            raise StorageError(f"Cannot append to {self.path}: {exc.strerror or exc}.") from exc


def read_events(path: str | os.PathLike | None) -> list[RunEvent]:
    """The events journaled in ``path``; a line cut short by a crash is skipped."""
    if path is None or not Path(path).exists():
        return []
    out: list[RunEvent] = []
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            try:
                out.append(RunEvent.from_dict(json.loads(line)))
            except (ValueError, KeyError, TypeError):
                continue
    return out


def _plain(obj: Any) -> Any:
    """``obj`` as JSON-ready data (numpy scalars and tuples included)."""
    return json.loads(json.dumps(obj, default=_default))


def _default(o: Any) -> Any:
    if hasattr(o, "item"):
        return o.item()
    if hasattr(o, "to_dict"):
        return o.to_dict()
    if isinstance(o, set | frozenset | tuple):
        return list(o)
    return str(o)
