"""One budget for a whole batch, shared by every worker, checked before every model call.

The batch's spend lives in a small SQLite *ledger*, ``DIR/budget.sqlite``: one row per model
request, written (state ``sent``, with the price the judge expects) *before* the request goes
out, turned into ``paid`` (with its real price) when the answer arrives, and deleted when no
answer came (an unanswered request costs nothing). A reservation is one ``BEGIN IMMEDIATE``
transaction that reads the limits and the totals and inserts the row, so two workers can never
both take the last call. The totals count paid rows *and* rows under way, so the batch sends at
most ``max_calls`` requests in all (money: up to the misestimate of the calls in flight).

Rows a killed process left ``sent`` are counted as spent (the server may have answered them);
the next batch over the folder marks them ``lost`` and keeps counting them, as a run's verdict
store does with its unsettled requests.

Who talks to the ledger:

- the process pool: every worker process opens the file itself (all on one machine);
- Ray: one :class:`LedgerActor`, pinned to the driver's node, owns the file and the workers call
  it (a SQLite file must not be shared over a network file system);

and each run's judge gets a :class:`SharedBudget` (a :class:`~intuitf.evaluator.budget.Budget`)
that reserves in the ledger before every request, next to the run's own limits, if any.
"""

from __future__ import annotations

import logging
import os
import socket
import sqlite3
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from intuitf.errors import BudgetExhausted, IntuitfError
from intuitf.evaluator.budget import Budget

log = logging.getLogger(__name__)

LEDGER_NAME = "budget.sqlite"

_SCHEMA = (
    """CREATE TABLE IF NOT EXISTS limits (
        id INTEGER PRIMARY KEY CHECK (id = 1),
        max_calls INTEGER,
        max_usd REAL
    )""",
    """CREATE TABLE IF NOT EXISTS spend (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        owner TEXT NOT NULL,
        volume TEXT NOT NULL,
        state TEXT NOT NULL,
        created REAL NOT NULL,
        estimate_usd REAL NOT NULL DEFAULT 0,
        usd REAL NOT NULL DEFAULT 0
    )""",
    "CREATE INDEX IF NOT EXISTS spend_state ON spend (state)",
)

#: What a row costs while its fate is unknown (sent, lost) and once paid.
_CALLS_USD = (
    "SELECT COUNT(*), COALESCE(SUM(CASE WHEN state = 'paid' THEN usd ELSE estimate_usd END), 0) "
    "FROM spend"
)


@dataclass(frozen=True)
class LedgerTotals:
    """The batch's spend: paid calls and dollars, requests under way, and requests whose
    process died while they were under way (``lost``: counted as spent)."""

    paid_calls: int
    paid_usd: float
    in_flight: int
    lost: int
    max_calls: int | None
    max_usd: float | None

    @property
    def calls(self) -> int:
        """Every request counted against the call limit."""
        return self.paid_calls + self.in_flight + self.lost

    @property
    def exhausted(self) -> bool:
        """No room left for one more call (calls), or the money is spent."""
        if self.max_calls is not None and self.calls >= self.max_calls:
            return True
        return self.max_usd is not None and self.paid_usd >= self.max_usd - 1e-12

    def to_dict(self) -> dict[str, Any]:
        return {
            "paid_calls": self.paid_calls,
            "paid_usd": self.paid_usd,
            "in_flight": self.in_flight,
            "lost": self.lost,
            "max_calls": self.max_calls,
            "max_usd": self.max_usd,
        }


class Ledger(Protocol):
    """What a :class:`SharedBudget` needs: the file itself, or the Ray actor in front of it."""

    def try_reserve(
        self, owner: str, volume: str, estimate_usd: float
    ) -> tuple[int | None, str]: ...

    def settle(self, row: int, usd: float) -> None: ...

    def release(self, row: int) -> None: ...

    def totals(self) -> LedgerTotals: ...


class BatchLedger:
    """The batch's spend in ``path`` (SQLite, WAL). Safe across processes and threads."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = str(path)
        self._lock = threading.Lock()
        try:
            Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(
                self.path, check_same_thread=False, isolation_level=None, timeout=60.0
            )
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=NORMAL")
            self._db.execute("PRAGMA busy_timeout=60000")
            for stmt in _SCHEMA:
                self._db.execute(stmt)
            self._db.execute(
                "INSERT OR IGNORE INTO limits (id, max_calls, max_usd) VALUES (1, NULL, NULL)"
            )
        except (sqlite3.Error, OSError) as exc:
            raise IntuitfError(
                f"The batch budget ledger {self.path} could not be opened: {exc}.",
                "Check that the batch folder is writable and on a local disk.",
            ) from None

    # -- limits ---------------------------------------------------------------------------
    def set_limits(self, max_calls: int | None, max_usd: float | None) -> None:
        """The batch's limits (None: no limit); they cover everything already spent."""
        with self._lock:
            self._db.execute(
                "UPDATE limits SET max_calls = ?, max_usd = ? WHERE id = 1",
                (None if max_calls is None else int(max_calls),
                 None if max_usd is None else float(max_usd)),
            )  # fmt: skip

    def limits(self) -> tuple[int | None, float | None]:
        with self._lock:
            row = self._db.execute("SELECT max_calls, max_usd FROM limits WHERE id = 1").fetchone()
        return (row[0], row[1]) if row else (None, None)

    def mark_lost(self) -> int:
        """Requests left ``sent`` by processes that are gone: mark them ``lost`` (still
        counted). Call only when no worker of this batch is running; returns how many."""
        with self._lock:
            cur = self._db.execute("UPDATE spend SET state = 'lost' WHERE state = 'sent'")
            return int(cur.rowcount or 0)

    # -- one request ----------------------------------------------------------------------
    def try_reserve(self, owner: str, volume: str, estimate_usd: float) -> tuple[int | None, str]:
        """Room for one request: (row id, "") or (None, why not). One atomic transaction."""
        est = max(0.0, float(estimate_usd))
        with self._lock:
            db = self._db
            db.execute("BEGIN IMMEDIATE")
            try:
                max_calls, max_usd = db.execute(
                    "SELECT max_calls, max_usd FROM limits WHERE id = 1"
                ).fetchone()
                calls, usd = db.execute(_CALLS_USD).fetchone()
                if max_calls is not None and calls + 1 > max_calls:
                    db.execute("ROLLBACK")
                    return None, (
                        f"The batch's call budget of {max_calls} calls is spent ({calls} sent "
                        "by all workers together)."
                    )
                if max_usd is not None and usd + est > max_usd + 1e-12:
                    db.execute("ROLLBACK")
                    return None, (
                        f"The batch's money budget is spent (${usd:.4f} of ${max_usd:.4f}; the "
                        f"next call would cost about ${est:.4f})."
                    )
                cur = db.execute(
                    "INSERT INTO spend (owner, volume, state, created, estimate_usd) "
                    "VALUES (?, ?, 'sent', ?, ?)",
                    (owner, volume, time.time(), est),
                )
                db.execute("COMMIT")
                return int(cur.lastrowid), ""
            except BaseException:
                if db.in_transaction:
                    db.execute("ROLLBACK")
                raise

    def settle(self, row: int, usd: float) -> None:
        """The request of ``row`` was answered: paid, at ``usd``."""
        with self._lock:
            self._db.execute(
                "UPDATE spend SET state = 'paid', usd = ? WHERE id = ?", (float(usd), int(row))
            )

    def release(self, row: int) -> None:
        """The request of ``row`` got no answer: nothing was paid."""
        with self._lock:
            self._db.execute("DELETE FROM spend WHERE id = ? AND state = 'sent'", (int(row),))

    # -- totals ---------------------------------------------------------------------------
    def totals(self) -> LedgerTotals:
        with self._lock:
            paid, usd = self._db.execute(
                "SELECT COUNT(*), COALESCE(SUM(usd), 0) FROM spend WHERE state = 'paid'"
            ).fetchone()
            sent = self._db.execute("SELECT COUNT(*) FROM spend WHERE state = 'sent'").fetchone()
            lost = self._db.execute("SELECT COUNT(*) FROM spend WHERE state = 'lost'").fetchone()
            max_calls, max_usd = self._db.execute(
                "SELECT max_calls, max_usd FROM limits WHERE id = 1"
            ).fetchone()
        return LedgerTotals(int(paid), float(usd), int(sent[0]), int(lost[0]), max_calls, max_usd)

    def per_volume(self) -> dict[str, int]:
        """Requests counted per volume (paid, under way or lost)."""
        with self._lock:
            rows = self._db.execute("SELECT volume, COUNT(*) FROM spend GROUP BY volume").fetchall()
        return {str(v): int(n) for v, n in rows}

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def __reduce__(self):  # a worker process opens the file itself
        return (BatchLedger, (self.path,))


def ledger_owner() -> str:
    """A name for this process's requests in the ledger (host, pid and a random tag)."""
    return f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


class SharedBudget(Budget):
    """A run's budget that also reserves every call in the batch's ledger.

    ``local`` is the run's own budget (its limits and what its verdict store says it paid), or
    None. A call goes out only when both have room; the ledger's answer comes first in the
    message when it refuses. When the ledger cannot be reached no call goes out.
    """

    def __init__(self, ledger: Ledger, volume: str, local: Budget | None = None) -> None:
        super().__init__(
            max_calls=local.max_calls if local is not None else None,
            max_usd=local.max_usd if local is not None else None,
        )
        if local is not None:
            self.calls, self.usd = local.calls, local.usd
            self._dearest = local._dearest
        self.ledger = ledger
        self.volume = str(volume)
        self.owner = ledger_owner()
        #: Ledger rows of this budget's calls under way, by the amount reserved for them.
        self._rows: dict[float, list[int]] = {}
        self._rows_lock = threading.Lock()

    def reserve(self, estimate_usd: float | None = None) -> float:
        est = super().reserve(estimate_usd)
        try:
            row, why = self.ledger.try_reserve(self.owner, self.volume, est)
        except Exception as exc:  # the ledger is unreachable: send nothing
            super().release(est)
            raise BudgetExhausted(
                f"The batch's budget ledger could not be reached ({exc}); no call was sent.",
                "Run the batch again: everything paid for is kept.",
            ) from None
        if row is None:
            super().release(est)
            raise BudgetExhausted(why, "Everything judged so far is kept; raise the batch's "
                                       "budget (--budget-calls / --budget-usd) and run it again.")  # fmt: skip
        with self._rows_lock:
            self._rows.setdefault(est, []).append(row)
        return est

    def _pop(self, reserved: float) -> int | None:
        with self._rows_lock:
            rows = self._rows.get(reserved)
            if not rows:  # should not happen; take any row of this budget
                rows = next((r for r in self._rows.values() if r), None)
            return rows.pop() if rows else None

    def settle(self, reserved: float, usd: float) -> None:
        super().settle(reserved, usd)
        row = self._pop(reserved)
        if row is not None:
            try:
                self.ledger.settle(row, usd)
            except Exception as exc:  # the call is done; the row stays counted as under way
                log.warning("could not record a paid call in the batch ledger: %s", exc)

    def release(self, reserved: float) -> None:
        super().release(reserved)
        row = self._pop(reserved)
        if row is not None:
            try:
                self.ledger.release(row)
            except Exception as exc:
                log.warning("could not release a call in the batch ledger: %s", exc)

    @property
    def under_way(self) -> int:
        """This budget's calls under way (reserved, not yet answered)."""
        with self._rows_lock:
            return sum(len(r) for r in self._rows.values())


def attach_shared_budget(judge: Any, ledger: Ledger, volume: str) -> SharedBudget | None:
    """Give ``judge`` (a model judge, which checks ``judge.budget`` before every request) a
    :class:`SharedBudget` over its own budget; None for judges that make no paid calls."""
    if judge is None or not hasattr(judge, "budget"):
        return None
    local = judge.budget if isinstance(judge.budget, Budget) else None
    if isinstance(local, SharedBudget):
        return local
    shared = SharedBudget(ledger, volume, local)
    judge.budget = shared
    return shared


# -- Ray ------------------------------------------------------------------------------------
class LedgerActorImpl:
    """The ledger behind a Ray actor (see :func:`ray_ledger`): one process owns the file."""

    def __init__(self, path: str) -> None:
        self._ledger = BatchLedger(path)

    def try_reserve(self, owner: str, volume: str, estimate_usd: float):
        return self._ledger.try_reserve(owner, volume, estimate_usd)

    def settle(self, row: int, usd: float) -> None:
        self._ledger.settle(row, usd)

    def release(self, row: int) -> None:
        self._ledger.release(row)

    def totals(self) -> LedgerTotals:
        return self._ledger.totals()


class RayLedgerClient:
    """The :class:`Ledger` interface over a Ray actor handle (picklable; for Ray workers)."""

    def __init__(self, handle: Any, timeout: float = 60.0) -> None:
        self.handle = handle
        self.timeout = float(timeout)

    def _get(self, ref):
        import ray

        return ray.get(ref, timeout=self.timeout)

    def try_reserve(self, owner: str, volume: str, estimate_usd: float):
        return self._get(self.handle.try_reserve.remote(owner, volume, estimate_usd))

    def settle(self, row: int, usd: float) -> None:
        self._get(self.handle.settle.remote(row, usd))

    def release(self, row: int) -> None:
        self._get(self.handle.release.remote(row))

    def totals(self) -> LedgerTotals:
        return self._get(self.handle.totals.remote())


def ray_ledger(path: str) -> RayLedgerClient:
    """Start the ledger actor on this (the driver's) node, owning the file at ``path``."""
    import ray
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    node = ray.get_runtime_context().get_node_id()
    actor = (
        ray.remote(num_cpus=0, max_concurrency=1)(LedgerActorImpl)
        .options(scheduling_strategy=NodeAffinitySchedulingStrategy(node_id=node, soft=False))
        .remote(str(path))
    )
    return RayLedgerClient(actor)
