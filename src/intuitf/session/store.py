"""RunStore: the runs under one folder, the tree their branches make, and every candidate.

A front end's history comes from here: :meth:`RunStore.runs` lists runs with their status
and cost, :meth:`RunStore.tree` nests branches under the run (and generation) they came from,
and :meth:`RunStore.candidate` finds any candidate a run ever rendered by a run-qualified id
such as ``foot-2/g003-007``. Everything is read from the run folders, so a restarted server
shows the same history.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

from intuitf.errors import SessionError
from intuitf.session.lock import in_use
from intuitf.session.rundir import RunDirectory
from intuitf.tf import GaussianTF

_ID = re.compile(r"^(?P<run>[^/\\]+)/(?P<cand>g\d{3,}-\d{3,})$")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,120}$")


@dataclass
class RunInfo:
    """A run at a glance."""

    name: str
    path: Path
    status: str  # "running" | "completed" | "budget" | "judge" | "cancelled" | ... | "stopped"
    generations_done: int
    generations: int
    cost: dict[str, Any]
    created: str
    volume: str
    intent: dict[str, Any]
    judge: str
    parent: dict[str, Any] | None
    message: str = ""
    #: How the intent was read on the volume (lines; see :mod:`intuitf.intent.readback`).
    understood: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        d = dict(self.__dict__)
        d["path"] = str(self.path)
        return d


@dataclass
class CandidateInfo:
    """One candidate of a run: its TF, where and how it ranked."""

    qid: str
    run: str
    id: str
    generation: int
    stage: str
    tf: GaussianTF
    rating: float
    rank: int
    origin: str = ""
    parents: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "qid": self.qid,
            "run": self.run,
            "id": self.id,
            "generation": self.generation,
            "stage": self.stage,
            "tf": self.tf.to_dict(),
            "rating": self.rating,
            "rank": self.rank,
            "origin": self.origin,
            "parents": list(self.parents),
        }


class RunStore:
    """The run folders directly under ``root``."""

    def __init__(self, root: str | os.PathLike) -> None:
        self.root = Path(root)

    # -- runs -----------------------------------------------------------------------------
    def path_of(self, name: str) -> Path:
        """The folder of run ``name`` (a plain folder name: no paths, no traversal)."""
        if not _NAME.match(name or ""):
            raise SessionError(f"{name!r} is not a run name.", "Use a name from the run list.")
        return self.root / name

    def new_name(self, base: str) -> str:
        """A run name from ``base`` that no folder under the root uses yet (``foot``,
        ``foot-2``, ...): the one naming rule of run folders, for every front end."""
        base = re.sub(r"[^A-Za-z0-9._-]+", "-", base).strip("-._")[:100].strip("-._") or "run"
        name, k = base, 1
        while (self.root / name).exists():
            k += 1
            name = f"{base}-{k}"
        return name

    def new_run_dir(self, base: str) -> Path:
        """The folder for a new run named after ``base`` (a volume's name, a title):
        ``ROOT/base``, or ``ROOT/base-2``, ... when taken (see :meth:`new_name`). The folder
        is not made here: :meth:`Session.open <intuitf.session.session.Session.open>` makes it
        and removes it again if the run cannot start."""
        return self.path_of(self.new_name(base))

    def names(self) -> list[str]:
        if not self.root.is_dir():
            return []
        return sorted(
            p.name for p in self.root.iterdir() if p.is_dir() and RunDirectory(p).exists()
        )

    def runs(self) -> list[RunInfo]:
        """Every run, oldest first."""
        out = []
        for name in self.names():
            try:
                out.append(self.run(name))
            except SessionError:
                continue  # a run folder being written, or damaged: not listed
        return sorted(out, key=lambda r: (r.created, r.name))

    def run(self, name: str) -> RunInfo:
        rd = RunDirectory(self.path_of(name))
        record = rd.read_run()
        plan = record.get("plan") or []
        ended = None
        generations_done = 0
        # How the words now asked were read: the opening's, or the last query's.
        understood = [str(x) for x in record.get("understood") or []]
        for e in rd.iter_journal():
            if e.get("type") == "end":
                ended = e
            elif e.get("type") == "generation" and isinstance(e.get("generation"), int):
                generations_done = max(generations_done, e["generation"] + 1)
                ended = None if ended and ended.get("generation", 0) <= e["generation"] else ended
            elif e.get("type") == "query":
                ended = None
                if isinstance(e.get("understood"), list):
                    understood = [str(x) for x in e["understood"]]
        ckpt = _read_json(rd.checkpoint) or {}
        if ckpt.get("plan"):
            plan = ckpt["plan"]
        if in_use(rd.root):
            status = "running"
        elif ended is not None:
            status = str(ended.get("reason", "stopped"))
        else:
            status = "stopped" if generations_done else "new"
        spec = record.get("spec") or {}
        parent = record.get("parent") or spec.get("parent")
        if parent and parent.get("run"):
            parent = {**parent, "run": Path(parent["run"]).name}
        cost = (ended or {}).get("cost") or ckpt.get("cost") or {}
        return RunInfo(
            name=name,
            path=rd.root,
            status=status,
            generations_done=generations_done,
            generations=sum(int(n) for _, n in plan) if plan else generations_done,
            cost=cost,
            created=str(record.get("created", "")),
            volume=str((record.get("volume") or {}).get("name", "")),
            intent=dict(record.get("intent") or {}),
            judge=str(record.get("judge", "")),
            parent=parent,
            message=str((ended or {}).get("message", "")),
            understood=understood,
        )

    # -- the tree -------------------------------------------------------------------------
    def history(self, name: str) -> list[dict[str, Any]]:
        """A run's generations in order: stage, best candidate, its rating, thumbnail path."""
        rd = RunDirectory(self.path_of(name))
        out = []
        for e in rd.generations():
            g = int(e["generation"])
            best = e.get("best_id")
            rating = next(
                (c.get("rating") for c in e.get("candidates", []) if c["id"] == best), None
            )
            thumb = rd.generation_sheet(g, best=True)
            out.append(
                {
                    "generation": g,
                    "stage": e.get("stage", ""),
                    "best": best,
                    "qid": f"{name}/{best}" if best else None,
                    "rating": rating,
                    "thumbnail": str(thumb) if thumb.exists() else None,
                    "match_stats": e.get("match_stats", {}),
                    "calls": e.get("calls", 0),
                }
            )
        return out

    def tree(self) -> list[dict[str, Any]]:
        """Runs nested under the run they branched from: ``{run, generations, children}``."""
        infos = {r.name: r for r in self.runs()}
        nodes: dict[str, dict[str, Any]] = {
            n: {"run": info.to_dict(), "generations": self.history(n), "children": []}
            for n, info in infos.items()
        }
        roots = []
        for n, info in infos.items():
            parent = (info.parent or {}).get("run")
            if parent in nodes and parent != n:
                nodes[parent]["children"].append(nodes[n])
            else:
                roots.append(nodes[n])
        return roots

    # -- candidates -----------------------------------------------------------------------
    def candidate(self, qid: str) -> CandidateInfo:
        """The candidate ``run/gGGG-NNN``, from the run's journal."""
        m = _ID.match(qid or "")
        if not m:
            raise SessionError(
                f"{qid!r} is not a candidate id.", "Write it as RUN/gGGG-NNN, e.g. foot-2/g003-007."
            )
        run, cid = m.group("run"), m.group("cand")
        rd = RunDirectory(self.path_of(run))
        if not rd.exists():
            raise SessionError(f"There is no run {run!r} in {self.root}.")
        # The generation it was made in (an elite reappears in later ones with the same id).
        for e in rd.generations():
            for c in e.get("candidates", []):
                if c.get("id") == cid:
                    return CandidateInfo(
                        qid=f"{run}/{cid}",
                        run=run,
                        id=cid,
                        generation=int(e["generation"]),
                        stage=str(e.get("stage", "")),
                        tf=GaussianTF.from_dict(c["tf"]),
                        rating=float(c.get("rating", float("nan"))),
                        rank=int(c.get("rank", 0)),
                        origin=str(c.get("origin", "")),
                        parents=list(c.get("parents", [])),
                    )
        raise SessionError(f"Run {run!r} has no candidate {cid!r}.", "Pick one from its history.")

    def save_edit(self, parent_qid: str, tf: GaussianTF, base: str = "edit") -> str:
        """Keep a hand-edited ``tf`` as a new point of the history; its run-qualified id.

        The edit becomes a small run folder ``edit``, ``edit-2``, ... with the parent run's
        spec (``initial`` = the edited TF, ``parent`` = the candidate it was edited from), the
        parent's intent pictures, and a journal holding one generation with one candidate
        (``g000-000``), so :meth:`runs`, :meth:`tree` and :meth:`candidate` list it and a
        branch or refinement can start from it like from any candidate.
        """
        import shutil
        import time

        from intuitf.session.rundir import atomic_write_json

        parent = self.candidate(parent_qid)
        prd = RunDirectory(self.path_of(parent.run))
        record = prd.read_run()
        self.root.mkdir(parents=True, exist_ok=True)
        while True:  # a folder no other edit took in the meantime
            name = self.new_name(base)
            root = self.path_of(name)
            try:
                root.mkdir()
                break
            except FileExistsError:
                continue
        rd = RunDirectory(root)
        cid = "g000-000"
        link = {"run": parent.run, "generation": parent.generation, "candidate": parent.id,
                "selected": []}  # fmt: skip
        spec = dict(record.get("spec") or {})
        if spec:
            spec.update(name=name, initial=[tf.to_dict()], parent=link)
        if (prd.root / "intent").is_dir():  # the spec's pictures are relative to the folder
            shutil.copytree(prd.root / "intent", root / "intent", dirs_exist_ok=True)
        rd.append_journal({"type": "stage", "generation": 0, "stage": "edit"})
        rd.append_journal(
            {
                "type": "generation",
                "generation": 0,
                "stage": "edit",
                "candidates": [
                    {
                        "id": cid,
                        "tf": tf.to_dict(),
                        "rating": parent.rating,
                        "rank": 1,
                        "origin": "hand edit",
                        "parents": [parent.qid],
                    }
                ],
                "best_id": cid,
                "calls": 0,
                "matches": [],
                "match_stats": {},
            }
        )
        rd.append_journal(
            {"type": "end", "generation": 1, "reason": "edited",
             "message": f"Edited by hand from {parent.qid}.", "cost": {}}
        )  # fmt: skip
        atomic_write_json(
            rd.run_json,
            {
                "kind": "edit",
                "spec": spec,
                "volume": record.get("volume"),
                "intent": record.get("intent"),
                "judge": record.get("judge", ""),
                "settings": record.get("settings", {}),
                "plan": [["edit", 1]],
                "initial": [tf.to_dict()],
                "parent": link,
                "versions": record.get("versions"),
                "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            },
        )
        return f"{name}/{cid}"

    def render(self, qid: str, size: int | None = None, volume: Any = None) -> np.ndarray:
        """A candidate's rendering from its run's judging camera (uint8 RGB).

        The run's volume is read from its spec unless ``volume`` is given.
        """
        from intuitf.render import Camera, VolumeRenderer
        from intuitf.session.building import spec_of_record
        from intuitf.session.settings import RunSettings

        info = self.candidate(qid)
        record = RunDirectory(self.path_of(info.run)).read_run()
        settings = RunSettings.from_dict(record.get("settings", {}))
        run_dir = self.path_of(info.run)
        vol = volume if volume is not None else spec_of_record(record).volume.load(run_dir)
        camera = Camera.from_dict(settings.camera) if settings.camera else Camera()
        r = VolumeRenderer(
            vol,
            size=size or settings.image_size,
            shading=settings.shading,
            background=tuple(settings.background),
            device=settings.device,
        )
        return r.render(info.tf, camera)


def _read_json(path: Path) -> dict | None:
    import json

    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
