"""The run directory: where a session keeps everything it has paid for.

This module alone knows the folder's layout; everything else asks a :class:`RunDirectory` for
its paths (``rd.run_json``, ``rd.best_file(1, ".tf.json")``, ...) or reads through
:class:`~intuitf.session.store.RunStore`. Layout::

    run.json            inputs, settings, seed, versions (written once, updated on resume)
    journal.jsonl       append-only; one JSON object per line (generation, stage, end, ...)
    events.jsonl        append-only; the run's numbered events (progress, verdicts, ...)
    checkpoint.json     the latest resumable state, replaced atomically
    checkpoints/        gen000.json ...: the state at the start of each generation (branching)
    verdicts.sqlite     every model verdict, keyed by the content of the question
    intent/             the intent's pictures (reference, sketch, base)
    best/               rank01.png, rank01.tf.json, rank01.tf.png, exports, summary.json
    generations/        gen000.png contact sheets, gen000-best.png
    evolution.png       ratings, calls, cost and time per generation
    report.html         a self-contained page with all of it
    .lock               held by the one process that drives the run (see ``lock``)

Every write is atomic (temporary file + rename) or an fsync'ed append, so a crash, a kill or a
full disk never leaves a half-written file behind.
"""

from __future__ import annotations

import errno
import json
import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from intuitf.errors import SessionError, StorageError


def _disk_full_error(path: Path, exc: OSError) -> StorageError:
    return StorageError(
        f"Cannot write {path}: the disk is full. Everything written before this point is kept.",
        "Free some space, then continue with --resume.",
    )


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see the old file or the new one, never half."""
    from intuitf.fileio import atomic_write_bytes as write

    write(path, data, error=StorageError, hint=None,
          full_hint="Free some space, then continue with --resume.")  # fmt: skip


def atomic_write_json(path: Path, obj: Any) -> None:
    atomic_write_bytes(path, (json.dumps(obj, indent=2) + "\n").encode("utf-8"))


def latest_generations(entries: Iterable[dict]) -> list[dict]:
    """The "generation" entries of a journal, one per generation, in order.

    A journal written before replays replaced their earlier entry may hold a generation twice
    (a generation replayed after a resume); the last wins.
    """
    by_gen: dict[int, dict] = {}
    for e in entries:
        if e.get("type") == "generation" and isinstance(e.get("generation"), int):
            by_gen[e["generation"]] = e
    return [by_gen[g] for g in sorted(by_gen)]


class RunDirectory:
    """Paths and safe reads/writes inside one run directory."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)

    # -- paths ----------------------------------------------------------------------------
    @property
    def run_json(self) -> Path:
        return self.root / "run.json"

    @property
    def journal(self) -> Path:
        return self.root / "journal.jsonl"

    @property
    def checkpoint(self) -> Path:
        return self.root / "checkpoint.json"

    @property
    def verdicts(self) -> Path:
        return self.root / "verdicts.sqlite"

    @property
    def best_dir(self) -> Path:
        return self.root / "best"

    @property
    def generations_dir(self) -> Path:
        return self.root / "generations"

    @property
    def events(self) -> Path:
        return self.root / "events.jsonl"

    def generation_checkpoint(self, generation: int) -> Path:
        """The saved state at the start of ``generation`` (after the one before it ended)."""
        return self.root / "checkpoints" / f"gen{generation:03d}.json"

    @property
    def best_summary(self) -> Path:
        """``best/summary.json``: ``{"best": [rank, rating and TF file of each kept result],
        "indistinct_generations": [...], "notes": [sentences]}`` (older runs: the list only)."""
        return self.best_dir / "summary.json"

    def best_stem(self, rank: int) -> Path:
        """``best/rankNN`` (no suffix): the stem of the rank-th result's files."""
        return self.best_dir / f"rank{int(rank):02d}"

    def best_file(self, rank: int = 1, suffix: str = ".png") -> Path:
        """A file of the rank-th result: ``.png`` (its rendering), ``.tf.json`` (its TF),
        ``.tf.png`` (the TF's plot), or an export's suffix."""
        stem = self.best_stem(rank)
        return stem.with_name(stem.name + suffix)

    def best_ranks(self) -> list[int]:
        """The ranks that have files in ``best/``, in order."""
        import re

        found = set()
        for p in self.best_dir.glob("rank*"):
            m = re.match(r"rank(\d+)\.", p.name)
            if m:
                found.add(int(m.group(1)))
        return sorted(found)

    def generation_sheet(self, generation: int, best: bool = False) -> Path:
        """``generations/genNNN.png`` (the contact sheet) or ``genNNN-best.png``."""
        tail = "-best" if best else ""
        return self.generations_dir / f"gen{int(generation):03d}{tail}.png"

    # -- lifecycle ------------------------------------------------------------------------
    def exists(self) -> bool:
        return self.run_json.exists()

    def create(self, *, overwrite: bool = False) -> None:
        """Make the directory for a new run; refuse to mix two runs in one folder."""
        if self.exists() and not overwrite:
            raise SessionError(
                f"{self.root} already holds a run.",
                "Continue it with --resume, or choose another output folder with -o.",
            )
        try:
            self.root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StorageError(
                f"Cannot create the run folder {self.root}: {exc.strerror or exc}."
            ) from exc
        if overwrite:
            for p in (self.journal, self.checkpoint):
                p.unlink(missing_ok=True)

    # -- records --------------------------------------------------------------------------
    def write_run(self, record: dict) -> None:
        atomic_write_json(self.run_json, record)

    def read_run(self) -> dict:
        try:
            return json.loads(self.run_json.read_text(encoding="utf-8"))
        except FileNotFoundError as exc:
            raise StorageError(
                f"{self.root} is not a run folder (no run.json).",
                "Point --resume at a folder written by `intuitf optimize`.",
            ) from exc
        except (OSError, json.JSONDecodeError) as exc:
            raise StorageError(f"{self.run_json} is unreadable or corrupt: {exc}.") from exc

    def append_journal(self, entry: dict) -> None:
        """Append one line and fsync it: the journal is the run's memory.

        A "generation" entry for a generation the journal already holds (a generation replayed
        after a kill between its journal entry and its checkpoint) replaces the earlier entries
        of that generation and later ones, so the journal keeps one entry per generation. The
        replayed entry carries everything paid since the last checkpoint, the killed attempt
        included, so nothing paid drops out of the figures.
        """
        if entry.get("type") == "generation" and isinstance(entry.get("generation"), int):
            self._drop_generations_from(entry["generation"])
        line = json.dumps(entry, separators=(",", ":")) + "\n"
        try:
            self.root.mkdir(parents=True, exist_ok=True)
            with open(self.journal, "a", encoding="utf-8") as fh:
                fh.write(line)
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as exc:
            if exc.errno == errno.ENOSPC:
                raise _disk_full_error(self.journal, exc) from exc
            raise StorageError(f"Cannot append to {self.journal}: {exc.strerror or exc}.") from exc

    def _drop_generations_from(self, generation: int) -> None:
        """Rewrite the journal (atomically) without its "generation" entries numbered
        ``generation`` or later; a no-op, with no rewrite, when it holds none."""
        if not self.journal.exists():
            return
        try:
            lines = self.journal.read_bytes().splitlines(keepends=True)
        except OSError as exc:
            raise StorageError(f"Cannot read {self.journal}: {exc.strerror or exc}.") from exc

        def stale(line: bytes) -> bool:
            if b'"generation"' not in line:
                return False
            try:
                e = json.loads(line)
            except (json.JSONDecodeError, UnicodeDecodeError):
                return False
            return (
                isinstance(e, dict)
                and e.get("type") == "generation"
                and isinstance(e.get("generation"), int)
                and e["generation"] >= generation
            )

        kept = [ln for ln in lines if not stale(ln)]
        if len(kept) == len(lines):
            return
        if kept and not kept[-1].endswith(b"\n"):
            kept[-1] += b"\n"  # a line cut short by a crash stays a line of its own
        atomic_write_bytes(self.journal, b"".join(kept))

    def read_journal(self) -> list[dict]:
        """All complete entries; a line cut short by a crash is ignored."""
        return list(self.iter_journal())

    def iter_journal(self) -> Iterator[dict]:
        """Journal entries in order; cut-short, garbled or non-object lines are skipped."""
        if not self.journal.exists():
            return
        with open(self.journal, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                line = line.strip()
                if not line:
                    continue
                try:
                    entry = json.loads(line)
                except json.JSONDecodeError:
                    continue
                if isinstance(entry, dict):
                    yield entry

    def generations(self) -> list[dict]:
        """One "generation" entry per generation, in order (see :func:`latest_generations`)."""
        return latest_generations(self.iter_journal())

    def write_checkpoint(self, state: dict) -> None:
        atomic_write_json(self.checkpoint, state)

    def write_generation_checkpoint(self, generation: int, state: dict) -> None:
        atomic_write_json(self.generation_checkpoint(generation), state)

    def read_checkpoint(self) -> dict | None:
        if not self.checkpoint.exists():
            return None
        try:
            return json.loads(self.checkpoint.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise StorageError(
                f"The checkpoint {self.checkpoint} is corrupt: {exc}.",
                "Delete it to restart the run from the beginning (paid verdicts stay cached).",
            ) from exc
