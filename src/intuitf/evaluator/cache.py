"""The verdict cache: answers already paid for, stored in SQLite by the content of the question.

This module is the evaluator's storage edge. Each answer is committed as it arrives (WAL mode), so
a crashed or interrupted run loses nothing it paid for, and a resumed run asks nothing twice. One
connection is shared by the asyncio tasks of a process, guarded by a lock (every operation is a
short synchronous statement, so no task holds the lock across an await).

Only real answers are stored: a tie caused by a refusal or an unreadable answer is not, so the
question is asked again next time.

**Spend.** The ``spend`` table records every paid request, usable answer or not, committed as
soon as the server answers: a row is written (state "sent", with the budget's estimate) just
before a request goes out and turned into "paid" (with its tokens and price) when the answer
arrives, or deleted when no answer came (a refused or unanswered request costs nothing). So
:meth:`VerdictCache.spent` is exact whatever happened to the process, and a row still "sent"
that another process left behind (it was killed while the request was under way) is reported
by :meth:`VerdictCache.unsettled`: a resumed run counts it against its budget, since the server
may have answered it.
"""

from __future__ import annotations

import hashlib
import json
import sqlite3
import threading
import time
import uuid
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from intuitf.errors import JudgeError
from intuitf.evaluator.types import Cost

_SCHEMA = """
CREATE TABLE IF NOT EXISTS answers (
    key TEXT PRIMARY KEY,
    judge TEXT NOT NULL,
    created REAL NOT NULL,
    payload TEXT NOT NULL
)
"""

_SPEND_SCHEMA = """
CREATE TABLE IF NOT EXISTS spend (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    owner TEXT NOT NULL,
    judge TEXT NOT NULL,
    state TEXT NOT NULL,
    created REAL NOT NULL,
    estimate_usd REAL NOT NULL DEFAULT 0,
    input_tokens INTEGER NOT NULL DEFAULT 0,
    output_tokens INTEGER NOT NULL DEFAULT 0,
    usd REAL NOT NULL DEFAULT 0
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
        #: Marks this process's spend rows, to tell them from rows a dead process left "sent".
        self._owner = uuid.uuid4().hex
        try:
            if self.path != ":memory:":
                Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
            if self.path != ":memory:":
                self._db.execute("PRAGMA journal_mode=WAL")
                self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.execute("PRAGMA busy_timeout=5000")
            self._db.execute(_SCHEMA)
            self._db.execute(_SPEND_SCHEMA)
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

    # -- spend ------------------------------------------------------------------------------

    def begin_spend(self, judge: str, estimate_usd: float = 0.0) -> int:
        """Record a request about to be sent; returns the row id for :meth:`settle_spend`."""
        with self._lock:
            cur = self._db.execute(
                "INSERT INTO spend (owner, judge, state, created, estimate_usd) "
                "VALUES (?, ?, 'sent', ?, ?)",
                (self._owner, judge, time.time(), float(estimate_usd)),
            )
            return int(cur.lastrowid)

    def settle_spend(
        self, row: int, input_tokens: int = 0, output_tokens: int = 0, usd: float = 0.0
    ) -> None:
        """The request of ``row`` was answered (usable or not): it is paid, with this price."""
        with self._lock:
            self._db.execute(
                "UPDATE spend SET state = 'paid', input_tokens = ?, output_tokens = ?, usd = ? "
                "WHERE id = ?",
                (int(input_tokens), int(output_tokens), float(usd), row),
            )

    def cancel_spend(self, row: int) -> None:
        """The request of ``row`` got no answer: nothing was paid."""
        with self._lock:
            self._db.execute("DELETE FROM spend WHERE id = ? AND state = 'sent'", (row,))

    def record_spend(
        self, judge: str, input_tokens: int = 0, output_tokens: int = 0, usd: float = 0.0
    ) -> None:
        """Record one answered request in one step (for judges that do not reserve first)."""
        self.settle_spend(self.begin_spend(judge), input_tokens, output_tokens, usd)

    def spent(self) -> Cost:
        """Every paid request recorded in this store: calls, tokens and dollars."""
        with self._lock:
            row = self._db.execute(
                "SELECT COUNT(*), COALESCE(SUM(input_tokens), 0), COALESCE(SUM(output_tokens), 0),"
                " COALESCE(SUM(usd), 0) FROM spend WHERE state = 'paid'"
            ).fetchone()
        return Cost(
            calls=int(row[0]), input_tokens=int(row[1]), output_tokens=int(row[2]), usd=row[3]
        )

    def unsettled(self) -> tuple[int, float]:
        """Requests another process sent and never settled (it died): count and estimated $."""
        with self._lock:
            row = self._db.execute(
                "SELECT COUNT(*), COALESCE(SUM(estimate_usd), 0) FROM spend "
                "WHERE state = 'sent' AND owner != ?",
                (self._owner,),
            ).fetchone()
        return int(row[0]), float(row[1])

    def clear_spend(self) -> None:
        """Forget all spend (a new run in this folder starts from nothing; answers stay)."""
        with self._lock:
            self._db.execute("DELETE FROM spend")

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
