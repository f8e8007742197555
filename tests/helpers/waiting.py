"""Waiting on a condition (a file appears, a status changes, a count grows), never on a clock.

``wait_for(pred)`` polls ``pred`` until it returns something truthy and returns that; the poll
interval only bounds how late the wait notices, it is not what the test relies on.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def wait_for(
    predicate: Callable[[], T], timeout: float = 120.0, poll: float = 0.02, what: str = ""
) -> T:
    """Poll ``predicate`` until it is truthy; its value. AssertionError after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        got = predicate()
        if got:
            return got
        if time.monotonic() > deadline:
            raise AssertionError(f"waited {timeout} s for {what or predicate!r}")
        time.sleep(poll)


def process_gone(pid: int) -> bool:
    """Whether no process has id ``pid`` any more (a zombie child counts as gone)."""
    import os

    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            return f.read().split(") ", 1)[1][:1] == "Z"
    except FileNotFoundError:
        return True
    except OSError:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        return False
