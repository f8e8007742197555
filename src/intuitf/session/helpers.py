"""Small helpers shared by the Session's modules."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from intuitf.evaluator.types import Cost, Intent
from intuitf.session.rundir import RunDirectory
from intuitf.session.settings import RunSettings
from intuitf.tf import GaussianTF
from intuitf.volume import Volume


def _palette_hint(intent: Intent, settings: RunSettings) -> list[tuple[float, float, float]]:
    """The colours the intent asks for, as a hint for the explorer (see ``RunSettings``)."""
    if not settings.palette_hint:
        return []
    from intuitf.intent.palette import intent_palette

    r, g, b = (float(c) for c in settings.background)
    return intent_palette(intent, background=(r, g, b))


def _read_intent(
    intent: Intent, settings: RunSettings, volume: Volume
) -> tuple[list[dict], list[str]]:
    """The Explorer's hints for the intent on the volume and how it was read, in lines a
    person can check (:func:`intuitf.intent.readback.read_back`), from one reading of it (a
    sketch's rays cast once); neither when the run does not use them (``material_hints``
    off)."""
    if not getattr(settings, "material_hints", True):
        return [], []
    from intuitf.intent.hints import explorer_hints, read_intent
    from intuitf.intent.readback import read_back

    camera = settings.camera or None
    reading = read_intent(intent, volume, camera=camera)
    return (explorer_hints(intent, volume, camera=camera, reading=reading),
            read_back(intent, volume, camera=camera, reading=reading))  # fmt: skip


def _with_selection(
    intent: Intent, volume: Volume, initial: Sequence[GaussianTF], settings: RunSettings
) -> Intent:
    """An edit intent with its base rendering and the mask of the selected features' pixels."""
    if intent.kind != "edit" or len(initial) != 1:
        return intent
    from intuitf.intent.selection import edit_intent

    return edit_intent(intent, volume, initial[0], settings)


def _judge_name(judge: Any) -> str:
    name = getattr(judge, "name", type(judge).__name__)
    try:
        from intuitf.evaluator.providers import redact_url
    except ImportError:  # pragma: no cover - older evaluator without the helper
        return str(name)
    return redact_url(str(name)) or ""


def _paid(judge: Any, cost: Cost, rd: RunDirectory | None) -> Cost:
    """``cost`` with calls, tokens and money as the run's verdict store recorded them (exact
    across resumes and kills), when the judge keeps its answers there."""
    from intuitf.evaluator.budget import run_spend, with_spend

    if rd is None:
        return cost
    return with_spend(cost, run_spend(judge, rd.verdicts))


def _intent_record(intent: Intent) -> dict:
    return {
        "kind": intent.kind,
        "text": intent.text,
        "about": intent.about,
        "selected": list(intent.selected),
        "has_reference": intent.reference is not None,
        "has_sketch": intent.sketch is not None,
        "has_base": intent.base is not None,
    }
