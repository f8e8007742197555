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
) -> tuple[list[dict], list[str], Any]:
    """The Explorer's hints for the intent on the volume, how it was read, in lines a
    person can check (:func:`intuitf.intent.readback.read_back`), and the reading itself
    (:class:`intuitf.intent.hints.IntentReading`), from one reading of it (a sketch's rays
    cast once); none of them when the run does not use them (``material_hints`` off)."""
    if not getattr(settings, "material_hints", True):
        return [], [], None
    from intuitf.intent.hints import explorer_hints, read_intent
    from intuitf.intent.readback import read_back

    camera = settings.camera or None
    reading = read_intent(intent, volume, camera=camera)
    return (explorer_hints(intent, volume, camera=camera, reading=reading),
            read_back(intent, volume, camera=camera, reading=reading), reading)  # fmt: skip


#: Largest picture (pixels a side) a sketch is fitted on: the strokes' colours, not detail.
SKETCH_FIT_SIZE = 128


def _fit_sketch(intent: Intent, settings: RunSettings, volume: Volume, reading: Any) -> Any:
    """A TF fitted to the sketch's strokes (:func:`intuitf.intent.sketch_fit.fit_sketch`) on
    the judging camera's pictures, each stroke measured over its structure as the offline
    judge measures it in the lit picture and by its colour in the unshaded one; None when the
    intent is no sketch, nothing was read of it, or the fit did no better than the strokes'
    hints."""
    if (
        intent.kind != "sketch"
        or not getattr(settings, "fit_sketch", True)
        or reading is None
        or not reading.strokes
        or not settings.camera
    ):
        return None
    from dataclasses import replace

    from intuitf.evaluator.metric import MetricJudge
    from intuitf.intent.regions import sketch_regions
    from intuitf.intent.sketch_fit import fit_sketch, material_errors, regions_on
    from intuitf.render import Camera, VolumeRenderer

    def view(shading: bool) -> Any:
        return VolumeRenderer(
            volume,
            size=min(int(settings.image_size), SKETCH_FIT_SIZE),
            shading=shading,
            background=tuple(settings.background),
            device=settings.device,
        ).sample_cache(camera)

    camera = Camera.from_dict(settings.camera)
    unshaded = view(False)
    shaded = view(True) if settings.shading else unshaded  # one view when the run is unlit
    judge = MetricJudge(cache_size=4)
    # Measured as the run's judge measures the strokes: over the structures they lie on.
    judged = replace(intent, part_regions=sketch_regions(intent, volume, camera))
    regions = regions_on(judged.part_regions, (unshaded.height, unshaded.width))

    def errors(tf: GaussianTF) -> Any:
        # Half the picture as the judge sees it, half the colour the TF gives each stroke's
        # structure (:func:`material_errors`, unshaded): the picture alone let the headlight's
        # highlights and what shows through stand in for the colour (the tooth's crown middle
        # turned towards orange under a yellow that looked right lit).
        seen = judge.stroke_errors(shaded.render(tf), judged)
        if seen is None or len(seen) != len(regions):
            return seen
        return 0.5 * (seen + material_errors(unshaded.render_rgba(tf), regions))

    fit = fit_sketch(reading.strokes, errors, seed=settings.seed)
    return fit if fit is not None and fit.improved else None


def _fit_line(fit: Any, intent: Intent, *, opening: bool = True) -> str:
    """The read-back line that says what the fit did, stroke by stroke."""
    from intuitf.intent.colours import colour_word
    from intuitf.intent.strokes import strokes_of

    strokes = strokes_of(intent.sketch, min_pixels=1) if intent.sketch is not None else []
    names = [colour_word(tuple(c / 255.0 for c in rgb)) for rgb, _ in strokes]
    if len(names) != len(fit.before):  # a stroke too small to measure: no names
        names = [f"stroke {k + 1}" for k in range(len(fit.before))]
    changes = ", ".join(
        f"{n} {b:.0f} → {a:.0f}" for n, b, a in zip(names, fit.before, fit.after, strict=True)
    )
    where = "the first generation" if opening else "the population"
    line = (
        f"A transfer function fitted to the strokes joins {where} (each stroke's colour"
        f" error as ΔE, the worst lowered first: {changes})"
    )
    return line + ("; the run judges against the strokes from the start." if opening else ".")


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
