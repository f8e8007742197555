"""The folders an agent may touch, and the check every path it names goes through.

``intuitf mcp`` reads volumes and pictures only under its ``--data`` roots (and the picture
folder it writes itself), keeps runs under ``--runs`` and writes exports and pictures only under
``--out``. A path an agent gives is resolved completely (``..`` and every symbolic link
followed) before it is compared with the roots, which are resolved the same way, so neither
traversal nor a link pointing outside gets through. A relative path is taken relative to the
first root of its kind.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from intuitf.errors import IntuitfError


class PathRefused(IntuitfError):
    """A path outside the roots the server was started with, or one it cannot use."""


def _resolved(path: str | os.PathLike) -> Path:
    return Path(path).expanduser().resolve()


@dataclass
class Roots:
    """``data``: folders to read volumes and pictures from; ``runs``: the run folders;
    ``out``: where exports and pictures are written (created on first use)."""

    data: list[Path] = field(default_factory=list)
    runs: Path = Path("runs")
    out: Path = Path("mcp-out")

    def __post_init__(self) -> None:
        self.data = [_resolved(p) for p in self.data]
        self.runs = _resolved(self.runs)
        self.out = _resolved(self.out)

    # -- checks ---------------------------------------------------------------------------
    def readable(self, path: str | os.PathLike, what: str = "file") -> Path:
        """``path`` resolved, if it exists under a data root or the output folder."""
        roots = [*self.data, self.out]
        p = self._inside(path, roots, what, base=self.data[0] if self.data else self.out)
        if not p.exists():
            raise PathRefused(
                f"There is no {what} {_shown(path)!r}.",
                "Use list_volumes to see the files the server may read.",
            )
        return p

    def writable(self, path: str | os.PathLike, what: str = "file") -> Path:
        """``path`` resolved (relative to the output folder), if it lies under it; its folder
        is created."""
        p = self._inside(path, [self.out], what, base=self.out)
        if p == self.out or p.is_dir() or str(path).rstrip().endswith(("/", ".")):
            raise PathRefused(
                f"{_shown(path)!r} is a folder, not a file to write.",
                "Give a file name, e.g. exports/foot-bone.vp.",
            )
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def run_folder(self, path: Path) -> Path:
        """A run folder under ``--runs`` (a run name never leads elsewhere, links included)."""
        return self._inside(path, [self.runs], "run folder", base=self.runs)

    def _inside(self, path, roots: list[Path], what: str, base: Path) -> Path:
        if not isinstance(path, str | os.PathLike) or not str(path).strip():
            raise PathRefused(f"No {what} path given.")
        if "\x00" in str(path):
            raise PathRefused(f"The {what} path contains a NUL character.")
        raw = Path(str(path)).expanduser()
        candidate = raw if raw.is_absolute() else base / raw
        try:
            p = candidate.resolve()
        except (OSError, RuntimeError) as exc:  # a link loop, an unreadable folder
            raise PathRefused(f"Cannot resolve the {what} path {_shown(path)!r}: {exc}.") from None
        if not any(p == r or p.is_relative_to(r) for r in roots):
            names = ", ".join(str(r) for r in roots) or "(none given)"
            raise PathRefused(
                f"The {what} {_shown(path)!r} is outside the folders this server may use.",
                f"Use a path under {names}.",
            )
        return p

    def to_dict(self) -> dict:
        return {"data": [str(p) for p in self.data], "runs": str(self.runs), "out": str(self.out)}


def _shown(path) -> str:
    return str(path)[:300]
