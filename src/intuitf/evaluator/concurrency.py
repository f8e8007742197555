"""How many requests a judge keeps in flight: additive increase, multiplicative decrease.

A server that is overwhelmed says so with timeouts, 429 and 503; one that keeps up answers in
time. :class:`AdaptiveLimit` starts at a profile's concurrency (1–2 for a local server), halves
the limit on a sign of overload (at most once per ``cooldown`` seconds, so a burst of failures
from one overload counts once) and adds one after as many answers in time as the limit is wide,
up to ``ceiling``. ``pause`` holds every new request back until a moment the server named
(``Retry-After``, ``retryDelay``), so waiting clients do not use up a low requests-per-minute
quota with requests that are bound to fail.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager


class AdaptiveLimit:
    """A concurrency limit that shrinks on overload and grows back (bound to one event loop)."""

    def __init__(self, start: int, ceiling: int, *, cooldown: float = 1.0) -> None:
        self.ceiling = max(1, int(ceiling))
        self.limit = float(min(max(1, int(start)), self.ceiling))
        self.cooldown = float(cooldown)
        self.in_flight = 0
        #: The widest the limit has been, and how often it was cut (for reports and tests).
        self.peak = int(self.limit)
        self.cuts = 0
        self._good = 0
        self._last_cut = -float("inf")
        self._resume_at = 0.0
        self._cond = asyncio.Condition()

    @property
    def width(self) -> int:
        return max(1, int(self.limit))

    @asynccontextmanager
    async def slot(self) -> AsyncIterator[None]:
        """Hold one of the limit's places while the body runs."""
        while True:
            wait = self._resume_at - time.monotonic()
            if wait <= 0:
                break
            await asyncio.sleep(wait)
        async with self._cond:
            await self._cond.wait_for(lambda: self.in_flight < self.width)
            self.in_flight += 1
        try:
            yield
        finally:
            async with self._cond:
                self.in_flight -= 1
                self._cond.notify_all()

    def answered(self) -> None:
        """An answer came back in time: widen by one after ``width`` such answers."""
        self._good += 1
        if self._good >= self.width and self.limit < self.ceiling:
            self._good = 0
            self.limit = min(self.ceiling, self.limit + 1)
            self.peak = max(self.peak, self.width)
            self._wake()

    def overloaded(self) -> bool:
        """A timeout, 429 or 503: halve the limit (once per cooldown). True if it was cut."""
        now = time.monotonic()
        self._good = 0
        if now - self._last_cut < self.cooldown or self.limit <= 1:
            return False
        self._last_cut = now
        self.limit = max(1.0, float(self.width // 2))
        self.cuts += 1
        return True

    def pause(self, seconds: float) -> None:
        """Start no new request for ``seconds`` (the server asked for it)."""
        self._resume_at = max(self._resume_at, time.monotonic() + max(0.0, seconds))

    def _wake(self) -> None:
        async def notify() -> None:
            async with self._cond:
                self._cond.notify_all()

        try:
            asyncio.get_running_loop().create_task(notify())
        except RuntimeError:
            pass
