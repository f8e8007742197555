"""Reading and writing transfer-function files."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from intuitf.errors import TransferFunctionError
from intuitf.tf.gaussian import GaussianTF


def load_tf(path: str | os.PathLike) -> GaussianTF:
    """Read a TF JSON file written by intuitf."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError as exc:
        raise TransferFunctionError(f"{p}: no such transfer-function file.") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise TransferFunctionError(f"{p}: cannot read the transfer function ({exc}).") from exc
    try:
        return GaussianTF.from_json(text)
    except TransferFunctionError as exc:
        raise TransferFunctionError(f"{p}: {exc.message}", exc.hint) from exc


def save_tf(tf: GaussianTF, path: str | os.PathLike) -> Path:
    """Write ``tf`` as JSON atomically (a crash never leaves half a file)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(tf.to_json())
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p
