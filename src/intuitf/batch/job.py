"""A batch as one call: plan the volumes, save the reference, hold the budget, run, summarise.

``DIR/`` holds::

    batch.json          what the batch is (reference, volumes, intent, judge, settings, budget)
    reference/          the reference picture, TF and histogram the workers use
    budget.sqlite       the shared budget's ledger (model judges)
    runs/KEY/           one run folder per volume (intuitf optimize --resume works on it)
    results/KEY.json    each volume's outcome, written when its run ends
    summary.json, contact_sheet.png, report.html

One batch process drives a folder at a time (``DIR/.lock``). Running the same command again,
or ``intuitf batch --resume DIR``, continues it: finished volumes are skipped, the others
resumed. A rerun may change the budget, the workers and the limits, not what the batch is.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from intuitf.batch.plan import VolumeItem, plan_volumes
from intuitf.batch.runner import (
    DEFAULT_MAX_FAILURES,
    DEFAULT_RAY_TIMEOUT,
    BatchConfig,
    drive,
)
from intuitf.batch.summary import DEFAULT_FLAG_BELOW, build_summary, write_summary
from intuitf.errors import IntuitfError

BATCH_VERSION = 1


@dataclass
class BatchRequest:
    """Everything ``intuitf batch`` takes, as data."""

    root: str
    reference: str | None = None
    volumes: list[str] = field(default_factory=list)
    text: str | None = None
    about: str | None = None
    evaluator: str = "metric"
    base_url: str | None = None
    judge_options: dict[str, Any] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    reader: dict[str, Any] = field(default_factory=dict)
    reference_volume: str | None = None
    carry: bool = True
    budget_calls: int | None = None
    budget_usd: float | None = None
    workers: int | None = None
    per_worker: int = 4
    #: None: the local process pool; "local": a local Ray instance; else a Ray address.
    ray: str | None = None
    max_concurrency: int | None = None
    rate_per_min: float | None = None
    flag_below: float = DEFAULT_FLAG_BELOW
    #: How many times a volume that failed (judge down, an error, its worker lost) goes again.
    max_failures: int = DEFAULT_MAX_FAILURES
    #: Seconds to wait for a Ray cluster to answer before giving up.
    ray_timeout: float = DEFAULT_RAY_TIMEOUT
    #: On a resume: "ray" or "pool" when the backend was taken from batch.json (None: given).
    backend_from_record: str | None = None


#: Fields of batch.json that make the batch what it is: a rerun must not change them.
_IDENTITY = ("reference_source", "template", "reader", "carry")


def _template(req: BatchRequest, root: Path) -> dict:
    judge: dict[str, Any] = {"spec": req.evaluator or "metric", "options": dict(req.judge_options)}
    if req.base_url:
        judge["base_url"] = req.base_url
    return {
        "intent": {
            "kind": "image",
            "reference": str(root / "reference" / "reference.png"),
            "text": req.text,
            "about": req.about,
        },
        "judge": judge,
        "settings": dict(req.settings),
    }


def _validate_template(template: dict) -> None:
    from intuitf.session.spec import parse_spec

    data = json.loads(json.dumps(template))
    data["intent"] = {**data["intent"], "kind": "text", "text": data["intent"].get("text") or "x"}
    parse_spec({**data, "volume": "phantom"})  # raises SessionError naming what is wrong


def _differences(old: dict, new: dict, prefix: str = "") -> list[str]:
    out = []
    for k in sorted(set(old) | set(new)):
        a, b = old.get(k), new.get(k)
        if isinstance(a, dict) and isinstance(b, dict):
            out += _differences(a, b, f"{prefix}{k}.")
        elif a != b:
            out.append(f"{prefix}{k}")
    return out


class BatchJob:
    """A batch folder being driven by this process (holds its lock until :meth:`close`)."""

    def __init__(self, req: BatchRequest) -> None:
        from intuitf.session.lock import RunLock

        self.root = Path(req.root).expanduser().absolute()
        self.req = req
        self.lock = RunLock(self.root)
        record_path = self.root / "batch.json"
        existing = record_path.exists()
        if existing and not req.volumes and not req.reference:
            req = self.req = _request_from_record(self.root, req)
        if not req.reference and not existing:
            raise IntuitfError(
                f"{self.root} holds no batch to resume.",
                "Give REFERENCE and VOLUMES to start one (intuitf batch REF VOLUMES -o DIR).",
            )
        if not req.volumes:
            raise IntuitfError("Give the VOLUMES to process (files, folders or globs).")
        _validate_template(_template(req, self.root))  # bad settings: nothing written yet
        self.lock.acquire()
        try:
            self._prepare(existing)
        except BaseException:
            self.lock.release()
            raise

    def _prepare(self, existing: bool) -> None:
        from intuitf.batch.reference import Reference, load_reference

        req, root = self.req, self.root
        template = _template(req, root)
        _validate_template(template)
        record: dict[str, Any] = {}
        if existing:
            record = json.loads((root / "batch.json").read_text(encoding="utf-8"))
        ref_source = str(Path(req.reference).expanduser().absolute()) if req.reference else None
        new_identity = {
            "reference_source": ref_source or record.get("reference_source"),
            "template": _comparable(template),
            "reader": req.reader,
            "carry": req.carry,
        }
        if existing:
            old_identity = {k: record.get(k) for k in _IDENTITY}
            old_identity["template"] = _comparable(old_identity.get("template") or {})
            diff = _differences(old_identity, json.loads(json.dumps(new_identity)))
            if diff:
                raise IntuitfError(
                    f"{root} holds a batch made with other choices ({', '.join(diff)}).",
                    f"Continue it as it was with `intuitf batch --resume {root}`, or give "
                    "another output folder with -o.",
                )
        ref_dir = root / "reference"
        if existing and (ref_dir / "reference.json").exists():
            self.reference = Reference.load_saved(ref_dir)
        else:
            camera = req.settings.get("camera") or None
            self.reference = load_reference(
                req.reference or "",
                reference_volume=req.reference_volume,
                reader=req.reader,
                size=int(req.settings.get("output_size", 512)),
                camera=camera,
            )
            self.reference.save(ref_dir)
        self.items: list[VolumeItem] = plan_volumes(req.volumes)
        from intuitf.session.rundir import atomic_write_json

        atomic_write_json(
            root / "batch.json",
            {
                "version": BATCH_VERSION,
                "reference_source": new_identity["reference_source"],
                "reference_kind": self.reference.kind,
                "reference_volume": req.reference_volume,
                "inputs": list(req.volumes),
                "items": [it.to_dict() for it in self.items],
                "template": template,
                "reader": req.reader,
                "carry": req.carry,
                "budget": {"calls": req.budget_calls, "usd": req.budget_usd},
                # Where it runs: a resume without --ray runs there again.
                "backend": {"ray": req.ray},
                "flag_below": req.flag_below,
                "created": record.get("created") or time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                "updated": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            },
        )
        self.config = BatchConfig(
            root=str(root),
            template=template,
            reader=dict(req.reader),
            carry=req.carry,
            per_worker=max(1, int(req.per_worker)),
        )
        self.ledger = None
        if self.config.uses_model:
            from intuitf.batch.budget import LEDGER_NAME, BatchLedger

            self.ledger = BatchLedger(root / LEDGER_NAME)
            stored = record.get("budget") or {}
            calls = req.budget_calls if req.budget_calls is not None else stored.get("calls")
            usd = req.budget_usd if req.budget_usd is not None else stored.get("usd")
            self.ledger.set_limits(calls, usd)
            self.lost = self.ledger.mark_lost()  # no worker runs now: their requests are gone
            rec = json.loads((root / "batch.json").read_text(encoding="utf-8"))
            rec["budget"] = {"calls": calls, "usd": usd}
            atomic_write_json(root / "batch.json", rec)

    def run(self, on_update=None, stop_when=None) -> dict:
        """Run every unfinished volume, then write and return the summary."""
        req = self.req
        t0 = time.perf_counter()
        results = drive(
            self.config,
            self.items,
            workers=req.workers,
            use_ray=req.ray is not None,
            ray_address=req.ray,
            on_update=on_update,
            ledger=self.ledger,
            stop_when=stop_when,
            max_concurrency=req.max_concurrency,
            rate_per_min=req.rate_per_min,
            max_failures=req.max_failures,
            ray_timeout=req.ray_timeout,
        )
        wall = time.perf_counter() - t0
        return self.summarise(results, wall)

    def summarise(self, results: dict | None = None, wall_s: float | None = None) -> dict:
        summary = build_summary(
            self.root,
            self.items,
            results or {},
            flag_below=self.req.flag_below,
            reference=self.reference.describe(),
            ledger=self.ledger.totals().to_dict() if self.ledger is not None else None,
            wall_s=wall_s,
            backend="ray" if self.req.ray is not None else "pool",
            workers=self.req.workers,
        )
        write_summary(self.root, summary)
        return summary

    def close(self) -> None:
        if self.ledger is not None:
            self.ledger.close()
        self.lock.release()

    def __enter__(self) -> BatchJob:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _comparable(template: dict) -> dict:
    """The template without what a rerun may change (judge timeouts and such)."""
    t = json.loads(json.dumps(template))
    t.get("judge", {}).pop("options", None)
    return t


def _request_from_record(root: Path, req: BatchRequest) -> BatchRequest:
    """A resume: the batch as batch.json records it, with this command's run options."""
    rec = json.loads((root / "batch.json").read_text(encoding="utf-8"))
    t = rec["template"]
    ray, backend_from_record = req.ray, None
    if ray is None:  # no --ray given: where the batch was started
        ray = (rec.get("backend") or {}).get("ray")
        backend_from_record = "pool" if ray is None else "ray"
    judge = t.get("judge", {})
    intent = t.get("intent", {})
    return BatchRequest(
        root=str(root),
        reference=rec.get("reference_source"),
        volumes=list(rec.get("inputs", [])),
        text=intent.get("text"),
        about=intent.get("about"),
        evaluator=req.evaluator
        if req.evaluator not in (None, "metric")
        else judge.get("spec", "metric"),
        base_url=req.base_url or judge.get("base_url"),
        judge_options={**judge.get("options", {}), **req.judge_options},
        settings=t.get("settings", {}),
        reader=rec.get("reader", {}),
        reference_volume=rec.get("reference_volume"),
        carry=rec.get("carry", True),
        budget_calls=req.budget_calls,
        budget_usd=req.budget_usd,
        workers=req.workers,
        per_worker=req.per_worker,
        ray=ray,
        max_concurrency=req.max_concurrency,
        rate_per_min=req.rate_per_min,
        max_failures=req.max_failures,
        ray_timeout=req.ray_timeout,
        backend_from_record=backend_from_record,
        flag_below=req.flag_below
        if req.flag_below != DEFAULT_FLAG_BELOW
        else rec.get("flag_below", DEFAULT_FLAG_BELOW),
    )


def run_batch(req: BatchRequest, on_update=None, stop_when=None) -> dict:
    """Plan, run and summarise the batch ``req`` describes; returns the summary.

    ``on_update(event, item, result)`` reports progress; ``stop_when()``, polled a few times a
    second, stops the batch like Ctrl-C when it returns true (every run is resumed later).
    """
    with BatchJob(req) as job:
        return job.run(on_update=on_update, stop_when=stop_when)


def request_dict(req: BatchRequest) -> dict:
    return asdict(req)


def default_workers() -> int:
    return os.cpu_count() or 1
