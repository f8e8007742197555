"""The one atomic file writer: readers see the old file or the new one, never half of one.

Every file intuitf writes (run folders, transfer functions, exports, pictures) goes through
:func:`atomic_write_bytes`: a temporary file in the same folder, flushed and fsync'ed, then
renamed over the target. A failure raises the caller's kind of
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


def atomic_write_text(path: str | os.PathLike, text: str, **kw) -> Path:
    """:func:`atomic_write_bytes` of ``text`` as UTF-8 with ``\\n`` line ends."""
    return atomic_write_bytes(path, text.encode("utf-8"), **kw)
