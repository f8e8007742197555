"""One run folder, one process: an exclusive lock on ``RUN/.lock`` for the life of a session.

The lock is an ``fcntl.flock`` on the file ``.lock`` in the run folder. The operating system
releases it when the process that holds it ends, however it ends (kill -9 included), so a lock
can never be left stale: the next process simply takes it. While holding the lock, the holder
writes who it is into the file (pid, host, start time, command line with any credentials in
URLs redacted), so a process that is refused can say which process drives the run, and a process
that finds a dead holder's record there can say that it takes over from it.

The file itself is never deleted (deleting a lock file lets two processes lock two different
files of the same name); a holder that releases the lock empties it, so a non-empty file whose
lock is free was left by a process that died.

flock locks belong to an open file, not to a process: a second :class:`RunLock` on the same
folder in the same process is refused too (two sessions must not drive one run in a web app
either).
"""

from __future__ import annotations

import json
import logging
import os
import socket
import sys
import time
from pathlib import Path

from intuitf.errors import RunLocked, StorageError

try:  # POSIX; on other systems runs are not locked (documented limitation)
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

log = logging.getLogger(__name__)

LOCK_NAME = ".lock"


def _command_line() -> str:
    from intuitf.evaluator.providers import redact_url

    argv = list(sys.argv) or ["python"]
    if argv and argv[0].endswith(("__main__.py", "intuitf")):
        argv[0] = "intuitf"
    return " ".join(redact_url(a) or "" for a in argv)


def _describe(holder: dict) -> str:
    pid = holder.get("pid", "?")
    host = holder.get("host")
    where = f" on {host}" if host and host != socket.gethostname() else ""
    started = holder.get("started")
    since = f", started {started}" if started else ""
    cmd = holder.get("command")
    what = f" ({cmd})" if cmd else ""
    return f"process {pid}{where}{what}{since}"


class RunLock:
    """An exclusive, process-lifetime lock on the run folder ``root``.

    ``acquire()`` takes it or raises :class:`~intuitf.errors.RunLocked` at once, naming the
    process that holds it; acquiring a lock already held by this object does nothing.
    ``release()`` gives it back (also done by the OS when the process ends). After an
    ``acquire()`` that found a dead holder's record, :attr:`took_over` holds that record and
    :attr:`takeover_message` a sentence to show the user.
    """

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)
        self.path = self.root / LOCK_NAME
        self._fd: int | None = None
        self.took_over: dict | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    @property
    def takeover_message(self) -> str | None:
        if not self.took_over:
            return None
        return (
            f"Taking over the run folder {self.root} from {_describe(self.took_over)}, "
            "which ended without releasing it."
        )

    def acquire(self) -> RunLock:
        if self._fd is not None or fcntl is None:
            return self
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise StorageError(
                f"Cannot lock the run folder {self.root}: {exc.strerror or exc}.",
                "Check that the folder is writable.",
            ) from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = _read_holder(fd)
            os.close(fd)
            who = _describe(holder) if holder else "another process"
            raise RunLocked(
                f"The run folder {self.root} is in use by {who}.",
                "Only one process may drive a run at a time: wait for it to finish, or stop it "
                "(its progress is kept) and then continue with `intuitf optimize --resume "
                f"{self.root}`.",
            ) from None
        previous = _read_holder(fd)
        self.took_over = previous or None
        if previous:
            log.warning("%s", self.takeover_message)
        record = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "command": _command_line(),
        }
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(record) + "\n").encode(), 0)
        except OSError:  # the record is a courtesy; the lock itself is what counts
            pass
        self._fd = fd
        return self

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            os.ftruncate(fd, 0)  # an empty file: released on purpose, nobody to take over from
        except OSError:
            pass
        try:
            fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)

    def holder(self) -> dict | None:
        """The record of the process that holds (or last held) the lock, if any."""
        try:
            with open(self.path, encoding="utf-8") as fh:
                return _parse(fh.read())
        except OSError:
            return None

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:  # a forgotten lock goes with its object, not only with the process
        try:
            self.release()
        except Exception:
            pass

    def __repr__(self) -> str:
        return f"RunLock({str(self.root)!r}, held={self.held})"


def _read_holder(fd: int) -> dict | None:
    try:
        data = os.pread(fd, 4096, 0)
    except OSError:
        return None
    return _parse(data.decode("utf-8", "replace"))


def _parse(text: str) -> dict | None:
    text = text.strip()
    if not text:
        return None
    try:
        rec = json.loads(text)
    except json.JSONDecodeError:
        return {"command": "unknown (unreadable lock record)"}
    return rec if isinstance(rec, dict) else None


def in_use(root: str | os.PathLike) -> bool:
    """Whether a process holds the lock of run folder ``root`` (asked without taking it)."""
    if fcntl is None:  # pragma: no cover - no locks on this system
        return False
    path = Path(root) / LOCK_NAME
    if not path.exists():
        return False
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    else:
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    finally:
        os.close(fd)
