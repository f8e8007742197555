"""How intuitf read an intent: lines a person can check before the first generation is judged.

Words are matched to materials and structures, a reference picture to layers, sketch strokes to
the values under them (:mod:`intuitf.intent.hints`, :mod:`intuitf.intent.strokes`). What was
matched where, what was not understood, and what a 1-D transfer function cannot do (two strokes
on one material) is said here in plain lines, so that a result in an unexpected colour is
explained before anyone wonders: the front ends show these lines with the run.

Pure computation on the intent and the volume (no I/O).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from intuitf.evaluator.types import Intent

if TYPE_CHECKING:
    from intuitf.intent.hints import IntentReading


def read_back(
    intent: Intent, volume, camera=None, structures=None, reading: IntentReading | None = None
) -> list[str]:
    """Lines saying how ``intent`` is read on ``volume`` (empty for an intent with nothing to
    read: no words, picture or sketch).

    ``camera`` (a ``Camera`` or its dict) is the one a sketch's base picture was rendered
    from; ``structures`` the volume's structure map when already at hand; ``reading`` the
    intent already read (:func:`~intuitf.intent.hints.read_intent`), as the Explorer's hints
    were made from it.
    """
    from intuitf.intent.hints import read_intent, structure_map_of

    value_range = tuple(getattr(volume, "value_range", (0.0, 1.0)))
    if intent.kind == "sketch":
        if intent.sketch is None or volume is None or not camera:
            return []
        from intuitf.intent.colours import colour_word

        reading = reading or read_intent(intent, volume, structures, camera)
        if not reading.strokes:
            return ["no stroke lies on the object: the sketch asks for nothing here"]
        lines = []
        for h in reading.strokes:
            line = (f"{colour_word(h.rgb)} stroke ({h.pixels} px): values around "
                    f"{_raw(h.center, value_range)}")  # fmt: skip
            lines.append("; ".join([line, *h.notes]))
        return lines
    if intent.kind == "none" or not (intent.text or intent.reference is not None):
        return []
    smap = structures if structures is not None else structure_map_of(volume)
    th = (reading or read_intent(intent, volume, smap, camera)).text
    lines = []
    for h in th.hints:
        look = ", ".join(x for x in (h.colour, h.opacity) if x) or "shown"
        lines.append(f'"{h.words}": {look}, {_place(h, smap, value_range, intent.kind)}')
    if not th.hints and intent.kind == "text":
        lines.append("no material or part named: the colours are left to the search")
    lines += th.notes
    if th.unknown:
        lines.append("not understood: " + ", ".join(th.unknown))
    return lines


def _place(h, smap, value_range, kind: str) -> str:
    """Where a hint landed, in words: the structure (its name, or its shape and place) and
    its values in the volume's own units."""
    if h.center is None:
        return "on the selected features" if kind == "edit" else "not found in this volume"
    where = f"values around {_raw(h.center, value_range)}"
    if h.structure is not None and smap is not None:
        try:
            s = smap.by_id(int(h.structure))
        except KeyError:
            return where
        what = s.name or f"{s.shape} at the {s.position}"
        return f"on S{s.id} ({what}), {where}"
    how = {"hounsfield": "by its CT values", "density order": "by density order",
           "main": "the volume's main material",
           "boundary": "the object's outer boundary"}.get(h.placed_by, "")  # fmt: skip
    where = f"{where} ({how})" if how else where
    if h.reach is not None and h.reach[1] > h.center:
        # Skin on a body's edge colours the body's values under it too (up to the bone).
        where += f", and the body under it, values up to {_raw(h.reach[1], value_range)}"
    return where


def _raw(v: float, value_range) -> str:
    lo, hi = value_range
    return f"{lo + float(v) * (hi - lo):.4g}"
