"""A run with a model judge asks that model, once per volume, to name the volume's structures.

At the opening of a new run, before the first generation's hints are built, the session sends
the one structure-atlas request (:mod:`intuitf.intent.atlas`: each structure rendered alone
with its descriptors) through the run's judge, so the call goes through the judge's retries,
budget and verdict store and counts in the run's spend. The names are kept with the volume's
structure map (in memory and in the on-disk cache, :mod:`intuitf.session.structure_cache`), so
the words of the intent match structures by name; a volume whose cached map already carries
names is not asked about again. A failed request is a warning: the run goes on with the
structures matched by their descriptors.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from dataclasses import dataclass, field
from typing import Any

from intuitf.evaluator.types import Cost

log = logging.getLogger(__name__)

__all__ = ["StructureNaming", "asks_names", "name_run_structures"]

#: Output tokens the answer may take: one short name per structure.
_OUTPUT_TOKENS = 600
#: The atlas pictures' size in pixels: enough to recognise a part, small enough to be cheap.
ATLAS_SIZE = 128


@dataclass
class StructureNaming:
    """What naming the structures did for a run (recorded in ``run.json`` as ``structures``)."""

    names: dict[int, str] = field(default_factory=dict)
    by: str | None = None  # the judge that named them (None: nobody)
    cached: bool = False  # the names came from the volume's cache: no request sent
    cost: Cost = field(default_factory=Cost)
    warning: str | None = None  # why the request failed (the run goes on without names)

    def to_dict(self) -> dict[str, Any]:
        return {
            "names": {f"S{k}": v for k, v in sorted(self.names.items())},
            "by": self.by,
            "cached": self.cached,
            "calls": self.cost.calls,
            "cost_usd": self.cost.usd,
            "warning": self.warning,
        }


def asks_names(judge: Any) -> bool:
    """Whether ``judge`` is a model judge that can be asked to name structures."""
    from intuitf.evaluator.mllm import MLLMJudge

    return isinstance(judge, MLLMJudge)


def name_run_structures(volume: Any, judge: Any, camera: Any = None) -> StructureNaming | None:
    """Name ``volume``'s structures with one atlas request through ``judge`` (a model judge).

    None when the judge is not a model judge. Names already cached for the volume are used
    without a request. Never raises for a failed request: the result carries the warning.
    """
    if not asks_names(judge):
        return None
    from intuitf.session.structure_cache import cached_structure_map, remember_names

    smap = cached_structure_map(volume)
    known = {s.id: s.name for s in smap.structures if s.name}
    if known:
        return StructureNaming(names=known, cached=True)
    if not smap.foreground():
        return StructureNaming(warning="The volume has no structures to name.")
    try:
        names, cost = _run(_ask(volume, smap, judge, camera))
    except Exception as exc:  # noqa: BLE001 - a failed naming never ends the run
        # What the failed tries paid is already in the judge's cost and the verdict store.
        why = str(getattr(exc, "message", None) or exc).rstrip(".")
        message = f"The model could not name the volume's structures ({why}); " \
                  "its words are matched to structures by their descriptors."  # fmt: skip
        log.warning("%s", message)
        return StructureNaming(by=getattr(judge, "name", None), warning=message)
    if not names:
        message = "The model's answer named none of the volume's structures; " \
                  "its words are matched to structures by their descriptors."  # fmt: skip
        log.warning("%s", message)
        return StructureNaming(by=getattr(judge, "name", None), cost=cost, warning=message)
    remember_names(volume, names)
    return StructureNaming(names=names, by=getattr(judge, "name", None), cost=cost)


async def _ask(volume: Any, smap: Any, judge: Any, camera: Any) -> tuple[dict[int, str], Cost]:
    """The request through the judge's own client (its retries, budget and spend records)."""
    from intuitf.evaluator.responses import _message
    from intuitf.intent.atlas import atlas_images, atlas_messages, parse_names

    images = atlas_images(volume, smap, camera, ATLAS_SIZE)
    messages = atlas_messages(smap, images, getattr(volume, "name", "") or "")
    prompt = " ".join(p.get("text", "") for p in messages[0]["content"] if p["type"] == "text")
    asker = _asker(judge)
    estimate = asker._estimate_usd(prompt, len(images))
    try:
        resp, cost = await asker._complete(messages, _SCHEMA, estimate, _OUTPUT_TOKENS)
    finally:
        await asker.aclose()  # its client belongs to this private event loop
        judge.cost += asker.cost  # what failed tries cost
        # A server that gave no answer at all is down for the run's judge too.
        judge._gave_up_at, judge._gave_up = asker._gave_up_at, asker._gave_up
        judge._heard_at = asker._heard_at
    judge.cost += cost
    text, _refusal, _finish = _message(resp)
    return parse_names(text or "", smap), cost


#: The answer's form for servers that take a JSON schema (names are free-form strings).
_SCHEMA = {
    "type": "json_schema",
    "json_schema": {
        "name": "structure_names",
        "strict": False,
        "schema": {
            "type": "object",
            "properties": {"names": {"type": "object", "additionalProperties": {"type": "string"}}},
            "required": ["names"],
        },
    },
}


def _asker(judge: Any) -> Any:
    """A copy of ``judge`` for the atlas request: the same server, budget and verdict store
    (so the call is paid from the run's budget and counted in its spend), but its own
    request profile, so what a server refuses about this unusual request (many pictures in
    one message) does not change how the run's comparisons are asked."""
    import copy

    asker = copy.copy(judge)
    asker.profile = copy.deepcopy(judge.profile)
    asker.adaptations = []
    asker.on_adapt = None
    asker.cost = Cost()
    asker._client = asker._limit = asker._lock = asker._loop = None
    return asker


def _run(coro: Any) -> Any:
    """Run ``coro`` to the end on a private event loop (in a thread when this one has a loop
    running, as in the web server)."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return asyncio.run(coro)
    out: dict[str, Any] = {}

    def work() -> None:
        try:
            out["value"] = asyncio.run(coro)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            out["error"] = exc

    t = threading.Thread(target=work, name="intuitf-structure-names")
    t.start()
    t.join()
    if "error" in out:
        raise out["error"]
    return out["value"]
