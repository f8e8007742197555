"""The verdict cache: answers already paid for, stored in SQLite by the content of the question.

This module is the evaluator's storage edge. Each answer is committed as it arrives (WAL mode), so
a crashed or interrupted run loses nothing it paid for, and a resumed run asks nothing twice. One
connection is shared by the asyncio tasks of a process, guarded by a lock (every operation is a
short synchronous statement, so no task holds the lock across an await).

Only real answers are stored: a tie caused by a refusal or an unreadable answer is not, so the
question is asked again next time.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
import threading
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from intuitf.errors import JudgeError

_SCHEMA = """
CREATE TABLE IF NOT EXISTS answers (
    key TEXT PRIMARY KEY,
    judge TEXT NOT NULL,
    created REAL NOT NULL,
    payload TEXT NOT NULL
)
"""


def request_key(judge: str, parts: Iterable[str | bytes | np.ndarray]) -> str:
    """A SHA-256 over the judge's name and every piece of the question, in order.

    Arrays contribute their shape, dtype and bytes; strings and bytes are length-prefixed so that
    different splits of the same characters cannot collide.
    """
    h = hashlib.sha256()
    h.update(judge.encode())
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p)
            h.update(f"|arr{a.shape}{a.dtype}|".encode())
            h.update(a.tobytes())
        else:
            b = p.encode() if isinstance(p, str) else bytes(p)
            h.update(f"|{len(b)}|".encode())
            h.update(b)
    return h.hexdigest()


class VerdictCache:
    """Paid answers by request key, in an SQLite file (or ``":memory:"``)."""

    def __init__(self, path: str | Path = ":memory:") -> None:
        self.path = str(path)
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0
        try:
            if self.path != ":memory:":
                Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
            if self.path != ":memory:":
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.execute("PRAGMA busy_timeout=5000")
            self._db.execute(_SCHEMA)
        except (sqlite3.Error, OSError) as exc:
            raise JudgeError(
                f"The verdict cache {self.path} could not be opened: {exc}.",
                "Check that the folder is writable and the file is an intuitf cache, or use another path.",
            ) from None

    def get(self, key: str) -> dict | None:
        """The stored answer for ``key``, or None."""
        with self._lock:
            row = self._db.execute("SELECT payload FROM answers WHERE key = ?", (key,)).fetchone()
        if row is None:
            self.misses += 1
            return None
        self.hits += 1
        return json.loads(row[0])

    def put(self, key: str, judge: str, payload: dict) -> None:
        """Store (and commit at once) the answer for ``key``."""
        text = json.dumps(payload, separators=(",", ":"))
        with self._lock:
            self._db.execute(
                "INSERT OR REPLACE INTO answers (key, judge, created, payload) VALUES (?, ?, ?, ?)",
                (key, judge, time.time(), text),
            )

    def __len__(self) -> int:
        with self._lock:
            return int(self._db.execute("SELECT COUNT(*) FROM answers").fetchone()[0])

    def __contains__(self, key: str) -> bool:
        with self._lock:
            return (
                self._db.execute("SELECT 1 FROM answers WHERE key = ?", (key,)).fetchone()
                is not None
            )

    def close(self) -> None:
        """Close the database (everything is already committed)."""
        with self._lock:
            self._db.close()

    def __enter__(self) -> VerdictCache:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"VerdictCache({self.path!r})"
