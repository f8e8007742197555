"""Writing exported transfer functions to files (the text itself comes from :mod:`.export`)."""

from __future__ import annotations

import os
from pathlib import Path

from intuitf.errors import TransferFunctionError
from intuitf.tf.export import EXPORT_FORMATS, export_tf
from intuitf.tf.gaussian import GaussianTF


def export_path(stem: str | os.PathLike, fmt: str) -> Path:
    """``stem`` with the file suffix of ``fmt`` (``best/rank01`` -> ``best/rank01.vp``)."""
    if fmt not in EXPORT_FORMATS:
        raise TransferFunctionError(
            f"Unknown export format {fmt!r}.", f"Choose one of: {', '.join(EXPORT_FORMATS)}."
        )
    p = Path(stem)
    return p.with_name(p.name + EXPORT_FORMATS[fmt])


def write_export(
    tf: GaussianTF,
    fmt: str,
    path: str | os.PathLike,
    value_range: tuple[float, float] | None = None,
    *,
    unit_distance: float = 1.0,
) -> Path:
    """Write ``tf`` in format ``fmt`` to ``path`` atomically and return the path."""
    text = export_tf(tf, fmt, value_range, unit_distance=unit_distance)
    from intuitf.fileio import atomic_write_text

    return atomic_write_text(
        path, text, error=TransferFunctionError, hint="Choose a folder you can write to."
    )
