"""``intuitf info`` and ``intuitf render``: look at a volume."""

from __future__ import annotations

import typer


def register(app: typer.Typer) -> None:
    """Add this module's commands to ``app``."""
    # Filled in by the renderer work: info, render.
    return None
