"""The words a multimodal model is asked: compare two renderings, aspect by aspect, answer in JSON.

The prompt is deterministic (the same question always reads the same, so answers can be cached
by content), names what the volume is only when the user said so (``Intent.about``), assumes no
domain and gives the model no persona. Aspects are listed as ``- [key] Name: description`` lines,
and the answer is a JSON object with, per aspect key, a short analysis and a choice among
:data:`CHOICES`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence

from intuitf.evaluator.compose import Layout
from intuitf.evaluator.types import Aspect, Intent

#: The three answers per aspect: Image 1 better, Image 2 better, or undecidable.
CHOICES = ("first", "second", "cannot decide")

#: What a model should answer when an image did not reach it (recognised by the parser).
CANNOT_SEE = "CANNOT SEE IMAGES"

#: Follow-ups when an answer was unusable (the judge asks again within its re-ask budget).
FOLLOW_UP_UNREADABLE = (
    "Your answer could not be read. Answer again with only the JSON object described above: "
    'no other text and no code fence; for each aspect key, a short "analysis" and a "choice" '
    'of "first", "second" or "cannot decide".'
)
FOLLOW_UP_TRUNCATED = (
    "Your answer was cut off before it ended. Answer again with only the JSON object described "
    "above, keeping each analysis to one short sentence."
)
FOLLOW_UP_REFUSAL = (
    "These are two renderings of scientific volume data, and the task is only to compare how "
    "well each shows the data. Please compare them on the listed aspects and answer with only "
    "the JSON object described above."
)

SYSTEM_PROMPT = (
    "You compare pictures made by direct volume rendering: the same volume rendered with "
    "different transfer functions, which map data values to colour and opacity. You judge only "
    "from what you see in the images, one aspect at a time, and you answer in the requested "
    "JSON format."
)


def answer_schema(aspects: Sequence[Aspect], intent: Intent) -> dict:
    """The JSON schema of an answer (strict: every property required, no extras)."""
    per_aspect = {
        "type": "object",
        "properties": {
            "analysis": {"type": "string"},
            "choice": {"type": "string", "enum": list(CHOICES)},
        },
        "required": ["analysis", "choice"],
        "additionalProperties": False,
    }
    keys = [a.key for a in aspects]
    props: dict = {}
    required: list[str] = []
    if intent.kind == "image":
        props["reference_description"] = {"type": "string"}
        required.append("reference_description")
    props["aspects"] = {
        "type": "object",
        "properties": {k: per_aspect for k in keys},
        "required": keys,
        "additionalProperties": False,
    }
    required.append("aspects")
    return {
        "type": "object",
        "properties": props,
        "required": required,
        "additionalProperties": False,
    }


def response_format(aspects: Sequence[Aspect], intent: Intent) -> dict:
    """The ``response_format`` request field for servers that support structured output."""
    return {
        "type": "json_schema",
        "json_schema": {
            "name": "rendering_comparison",
            "strict": True,
            "schema": answer_schema(aspects, intent),
        },
    }


def _intent_paragraph(intent: Intent) -> str:
    if intent.kind == "text":
        return (
            "The user describes what they want to see:\n"
            f'"{(intent.text or "").strip()}"\n'
            "Judge the candidates against this description."
        )
    if intent.kind == "image":
        return (
            "The user gave a reference image (labelled 'Reference image') whose style the "
            "candidates should match. First interpret the reference: describe which structures "
            "it shows, their colours and their opacity (what is opaque, what is semi-transparent "
            "context); ignore its background colour. Write that description in "
            '"reference_description", then judge the candidates against it.'
        )
    if intent.kind == "sketch":
        extra = f'\nThe user also wrote: "{intent.text.strip()}"' if intent.text else ""
        return (
            "The user drew coloured strokes over a rendering (labelled 'Sketch'). Each stroke "
            "means: make the structure under this stroke this colour. Judge how well each "
            "candidate honours the strokes." + extra
        )
    if intent.kind == "edit":
        return (
            "The user selected a feature of the rendering labelled 'Before the edit' and asked "
            f'for this change to it:\n"{(intent.text or "").strip()}"\n'
            + (
                "The image labelled 'Selection' shows the selected feature outlined in magenta. "
                if intent.selection_mask is not None and intent.selection_mask.any()
                else ""
            )
            + "The change should happen in the selected feature, and everything else should "
            "stay as it was before the edit."
        )
    return "Judge the candidates on the quality of the visualisation alone."


def user_prompt(aspects: Sequence[Aspect], intent: Intent, layout: Layout = "parts") -> str:
    """The instruction text that precedes the images."""
    if layout == "side_by_side":
        where = (
            "one picture, side by side: Image 1 on the left and Image 2 on the right, each "
            "labelled above"
        )
    else:
        where = "two images, labelled 'Image 1' and 'Image 2'"
    lines = [
        f"Below are two renderings of the same volume, made with different transfer functions, "
        f"as {where}.",
    ]
    if intent.about:
        lines.append(f"The volume is: {intent.about.strip()}.")
    lines += [
        "",
        _intent_paragraph(intent),
        "",
        "Compare the two candidates on these aspects, one at a time:",
    ]
    for a in aspects:
        lines.append(f"- [{a.key}] {a.name}: {a.description}")
    schema = json.dumps(answer_schema(aspects, intent), separators=(",", ":"))
    lines += [
        "",
        "For each aspect, write a short analysis (one or two sentences that compare the two "
        'images), then choose "first" if Image 1 is better, "second" if Image 2 is better, or '
        '"cannot decide" if they are equally good on that aspect. Use "cannot decide" sparingly.',
        "Answer with a single JSON object, keyed by the aspect keys in square brackets, that "
        "follows this JSON schema:",
        schema,
        f"If you cannot see all the images, answer only: {CANNOT_SEE}",
    ]
    return "\n".join(lines)
