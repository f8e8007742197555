"""Reading and writing transfer-function files."""

from __future__ import annotations

import os
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
    from intuitf.fileio import atomic_write_text

    return atomic_write_text(path, tf.to_json(), error=TransferFunctionError)
