"""Where a session's record goes: its journal, checkpoints, events and generation pictures.

A :class:`Session` writes through one recorder and never spells a path:

- :class:`FolderRecorder` writes into a run folder (:class:`~intuitf.session.rundir.
  RunDirectory`, the one place that knows the folder's layout): fsync'ed journal lines, atomic
  checkpoints (the latest and one per generation, so a branch can start from any of them),
  the events file and the contact sheets.
- :class:`MemoryRecorder` keeps the journal and the latest checkpoint in memory: a run without a
  folder (notebooks, tests) records the same entries, and a test can read them back.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from intuitf.session.rundir import RunDirectory, atomic_write_bytes

__all__ = ["FolderRecorder", "MemoryRecorder", "RunRecorder", "recorder_for"]


class RunRecorder:
    """What a session records, wherever it goes (see the module notes)."""

    #: Whether what is recorded outlives the process (a resume can continue from it).
    persistent: bool = False
    #: Whether generation pictures (contact sheets, the best's thumbnail) are kept.
    keeps_pictures: bool = False

    @property
    def events_path(self) -> Path | None:
        """The file the run's events are journaled to (None: kept in memory only)."""
        return None

    def journal(self, entry: dict[str, Any]) -> None:
        """Append one journal entry."""
        raise NotImplementedError

    def checkpoint(self, generation: int, state: dict[str, Any]) -> None:
        """Keep ``state``, the resumable state at the start of ``generation``."""
        raise NotImplementedError

    def generation_pictures(self, generation: int, sheet: bytes, best: bytes) -> None:
        """Keep a generation's contact sheet and its best's picture (PNG bytes)."""


class FolderRecorder(RunRecorder):
    """Records into a run folder (see :mod:`intuitf.session.rundir` for the layout)."""

    persistent = True
    keeps_pictures = True

    def __init__(self, run_dir: RunDirectory) -> None:
        self.run_dir = run_dir

    @property
    def events_path(self) -> Path | None:
        return self.run_dir.events

    def journal(self, entry: dict[str, Any]) -> None:
        self.run_dir.append_journal(entry)

    def checkpoint(self, generation: int, state: dict[str, Any]) -> None:
        self.run_dir.write_checkpoint(state)
        # Kept per generation too: a branch can start from any generation and reproduce it.
        self.run_dir.write_generation_checkpoint(generation, state)

    def generation_pictures(self, generation: int, sheet: bytes, best: bytes) -> None:
        atomic_write_bytes(self.run_dir.generation_sheet(generation), sheet)
        atomic_write_bytes(self.run_dir.generation_sheet(generation, best=True), best)


class MemoryRecorder(RunRecorder):
    """Records in memory: :attr:`entries` (the journal) and :attr:`last_checkpoint`."""

    def __init__(self) -> None:
        self.entries: list[dict[str, Any]] = []
        self.last_checkpoint: dict[str, Any] | None = None
        #: The generations a checkpoint was taken at, in order.
        self.checkpoints: list[int] = []

    def journal(self, entry: dict[str, Any]) -> None:
        self.entries.append(dict(entry))

    def checkpoint(self, generation: int, state: dict[str, Any]) -> None:
        self.last_checkpoint = state
        self.checkpoints.append(generation)


def recorder_for(run_dir: RunDirectory | None) -> RunRecorder:
    """A :class:`FolderRecorder` for a run folder, a :class:`MemoryRecorder` without one."""
    return FolderRecorder(run_dir) if run_dir is not None else MemoryRecorder()
