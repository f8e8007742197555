"""The one atomic file writer: readers see the old file or the new one, never half of one.

Every file intuitf writes (run folders, transfer functions, exports, pictures) goes through
:func:`atomic_write_bytes`: a temporary file in the same folder, flushed and fsync'ed, then
renamed over the target. The file gets the mode any newly created file gets (0666 less the
process umask; an existing file keeps its mode), so other users and workers on a shared file
system read it as they read anything else. A failure raises the caller's kind of
:class:`~intuitf.errors.IntuitfError` naming the file; a full disk says so.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

from intuitf.errors import IntuitfError


def atomic_write_bytes(
    path: str | os.PathLike,
    data: bytes,
    *,
    error: type[IntuitfError] = IntuitfError,
    hint: str | None = "Check that the folder exists and is writable, or choose another path.",
    full_hint: str = "Free some space and try again.",
) -> Path:
    """Write ``data`` to ``path`` atomically; raise ``error`` (with ``hint``) if it cannot."""
    p = Path(path)
    tmp: str | None = None
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
        # mkstemp creates 0600 files; give the file the mode open() would have given it.
        os.fchmod(fd, _mode_for(p))
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except OSError as exc:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        if exc.errno == errno.ENOSPC:
            raise error(
                f"Cannot write {p}: the disk is full. Everything written before this point is "
                "kept.",
                full_hint,
            ) from exc
        raise error(f"Cannot write {p}: {exc.strerror or exc}.", hint) from exc
    except BaseException:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise
    return p


def _mode_for(path: Path) -> int:
    """The permission bits a plain ``open(path, "w")`` would leave ``path`` with."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        return 0o666 & ~_umask()


def _umask() -> int:
    """The process umask, read without changing it where the system allows (Linux)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)  # elsewhere the only way to read it is to set it and set it back
    os.umask(mask)
    return mask


def atomic_write_text(path: str | os.PathLike, text: str, **kw) -> Path:
    """:func:`atomic_write_bytes` of ``text`` as UTF-8 with ``\\n`` line ends."""
    return atomic_write_bytes(path, text.encode("utf-8"), **kw)
