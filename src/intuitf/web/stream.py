"""Run progress as server-sent events: every event of a run, live or replayed from its journal.

``GET /api/runs/{name}/events`` sends each event as ``id: SEQ``, ``event: TYPE`` and
``data: JSON``. ``?since=N`` or the ``Last-Event-ID`` header (which browsers send when they
reconnect) replays the events after N first, so a page that connects late, reloads, or meets
a restarted server misses nothing. The stream follows the run when it is live here, replays
``events.jsonl`` when it is not, and picks the run up again when it becomes live (a
``/continue``). A comment line every ``keepalive`` seconds keeps proxies and the browser from
closing an idle stream.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator

from intuitf.session.events import RunEvent, read_events
from intuitf.session.rundir import RunDirectory

_CLOSED = object()


def format_event(e: RunEvent) -> str:
    data = json.dumps(e.to_dict(), separators=(",", ":"))
    return f"id: {e.seq}\nevent: {e.type}\ndata: {data}\n\n"


async def run_events(web, name: str, since: int, keepalive: float) -> AsyncIterator[str]:
    """The SSE text of run ``name``'s events after ``since``, then of every new one."""
    registry = web.registry
    path = RunDirectory(web.store.path_of(name)).events
    last = max(0, int(since))
    yield f"retry: 2000\n: events of {name} after {last}\n\n"
    while not web.stopping:
        changed = registry.changed_event()
        live = registry.get(name)
        if live is not None:
            loop = asyncio.get_running_loop()
            queue: asyncio.Queue = asyncio.Queue()

            def push(e, loop=loop, queue=queue) -> None:
                try:
                    loop.call_soon_threadsafe(queue.put_nowait, e)
                except RuntimeError:  # the server's loop is closing
                    pass

            unsubscribe = live.session.events.subscribe(push, since=last)
            closed = asyncio.ensure_future(live.wait_closed())
            closed.add_done_callback(lambda _f, q=queue: q.put_nowait(_CLOSED))
            stop = lambda q=queue: q.put_nowait(_CLOSED)  # noqa: E731
            web.on_stop(stop)
            try:
                while True:
                    try:
                        item = await asyncio.wait_for(queue.get(), keepalive)
                    except TimeoutError:
                        yield ": keep-alive\n\n"
                        continue
                    if item is _CLOSED:
                        break
                    if item.seq <= last:
                        continue
                    last = item.seq
                    yield format_event(item)
            finally:
                unsubscribe()
                closed.cancel()
                web.forget_stop(stop)
            continue
        # Not live here: what the run folder's journal holds, then wait for news.
        events = await asyncio.to_thread(read_events, path)
        for e in events:
            if e.seq > last:
                last = e.seq
                yield format_event(e)
        try:
            await asyncio.wait_for(changed.wait(), keepalive)
        except TimeoutError:
            yield ": keep-alive\n\n"
