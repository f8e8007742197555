"""Reading model answers: JSON, fenced JSON, free text, refusals and garbage."""

from __future__ import annotations

import json

import pytest

from intuitf.evaluator.parsing import UnreadableAnswer, normalise_choice, parse_answer
from intuitf.evaluator.types import Choice
from intuitf.intent.aspects import aspects_for

Q = aspects_for("quality")
F, S, T = Choice.FIRST, Choice.SECOND, Choice.TIE


@pytest.mark.parametrize(
    "word, choice",
    [
        ("first", F), ("Second", S), ("cannot decide", T), ("1", F), ("2", S), ("3", T),
        ("A", F), ("b", S), ("Image 1", F), ("**Image 2**", S), ("left", F), ("right", S),
        ("tie", T), ("The first image is better", F), (2, S), ("banana", None),
    ],
)  # fmt: skip
def test_choice_words(word, choice):
    assert normalise_choice(word) is choice


def test_schema_json():
    text = json.dumps(
        {
            "aspects": {
                "information_richness": {"analysis": "more visible", "choice": "first"},
                "feature_discrimination": {"analysis": "clearer edges", "choice": "second"},
                "color_content_harmony": {"analysis": "same", "choice": "cannot decide"},
            }
        }
    )
    p = parse_answer(text, Q)
    assert p.per_aspect == {
        "information_richness": F,
        "feature_discrimination": S,
        "color_content_harmony": T,
    }
    assert p.rationale["feature_discrimination"] == "clearer edges"
    assert p.missing == []


def test_fenced_json_in_prose_with_names_and_missing_aspect():
    text = (
        "Here is my comparison.\n```json\n"
        '{"Information richness": "Image 2", "feature_discrimination": {"answer": "A"}}\n'
        "```\nHope this helps."
    )
    p = parse_answer(text, Q)
    assert p.per_aspect == {
        "information_richness": S,
        "feature_discrimination": F,
        "color_content_harmony": T,
    }
    assert p.missing == ["color_content_harmony"]


def test_json_list_form_and_reference_description():
    text = json.dumps(
        {
            "reference_description": "white bone, faint red skin",
            "aspects": [
                {"aspect": "color_style_matching", "choice": "second"},
                {"aspect": "structural_style_matching", "choice": "first"},
            ],
        }
    )
    p = parse_answer(text, aspects_for("image"))
    assert p.per_aspect == {"color_style_matching": S, "structural_style_matching": F}
    assert p.reference_description == "white bone, faint red skin"


def test_free_text_keyed_lines():
    text = (
        "1. Information richness: Image 1 shows more, Image 2 is hazy.\n"
        "Final answer:\n[information_richness]: first\n[feature_discrimination]: second\n"
        "[color_content_harmony]: cannot decide\n"
    )
    p = parse_answer(text, Q)
    assert list(p.per_aspect.values()) == [F, S, T]


def test_free_text_final_answer_digits_only_reads_that_line():
    # Digits in the analysis must not be counted (unlike a parse of everything after the marker).
    text = "Image 1 has 2 bones visible, Image 2 has 3.\nFinal answer: 2 1 3\nThanks 1 1 1"
    p = parse_answer(text, Q)
    assert list(p.per_aspect.values()) == [S, F, T]


def test_single_aspect_plain_word():
    assert parse_answer("Final answer: B", aspects_for("text")).per_aspect == {"text_alignment": S}
    assert parse_answer('{"choice": "first"}', aspects_for("text")).per_aspect == {
        "text_alignment": F
    }


@pytest.mark.parametrize(
    "text, reason",
    [
        ("I'm sorry, but I can't help with that.", "refusal"),
        ("I cannot see the image. Please upload it.", "blind"),
        ("CANNOT SEE IMAGES", "blind"),
        ("}{ ::: garbage ::: {{", "unreadable"),
        ('{"aspects": {"information_richness": {"analysis": "x", "cho', "unreadable"),
        ("", "unreadable"),
        (None, "unreadable"),
    ],
)
def test_unusable_answers(text, reason):
    with pytest.raises(UnreadableAnswer) as exc:
        parse_answer(text, Q)
    assert exc.value.reason == reason


# -- answers of reasoning models and prose comparisons (each failed before the robust reader) --


def _schema(choice_ir="first", choice_fd="second"):
    return json.dumps(
        {
            "aspects": {
                "information_richness": {"analysis": "a", "choice": choice_ir},
                "feature_discrimination": {"analysis": "b", "choice": choice_fd},
                "color_content_harmony": {"analysis": "c", "choice": "cannot decide"},
            }
        }
    )


def test_prose_image_2_better_than_image_1_is_a_vote_for_the_second():
    text = "Final answer:\n[information_richness]: Image 2 is better than Image 1"
    assert parse_answer(text, Q).per_aspect["information_richness"] is S
    assert normalise_choice("Image 2 is better than Image 1") is S
    assert normalise_choice("Image 1 is worse than Image 2") is S
    assert normalise_choice("I prefer the second image over the first") is S
    assert normalise_choice("Image 1 is clearer than Image 2") is F


def test_think_block_with_braces_before_the_json():
    text = (
        '<think>Let me weigh {information} vs {features}; maybe {"choice": "second"}?'
        "</think>\n" + _schema()
    )
    p = parse_answer(text, Q)
    assert list(p.per_aspect.values()) == [F, S, T]


def test_thought_block_and_unclosed_reasoning_are_dropped():
    assert (
        parse_answer("<thought>{x}</thought>" + _schema(), Q).per_aspect["information_richness"]
        is F
    )
    # The chat template put the opening tag into the prompt: only the closing tag is seen.
    assert (
        parse_answer("weighing {a} and {b}</think>" + _schema("second"), Q).per_aspect[
            "information_richness"
        ]
        is S
    )
    with pytest.raises(UnreadableAnswer):
        parse_answer("<think>still thinking about " + _schema(), Q)


def test_draft_json_followed_by_the_final_one_reads_the_final_one():
    text = "Draft: " + _schema("first") + "\nOn reflection, the final answer:\n" + _schema("second")
    assert parse_answer(text, Q).per_aspect["information_richness"] is S


def test_list_of_parts_content_is_read_from_its_text_parts():
    parts = [
        {
            "type": "reasoning",
            "text": '{"aspects": {"information_richness": {"choice": "second"}}}',
        },
        {"type": "text", "text": _schema("first")},
    ]
    assert parse_answer(parts, Q).per_aspect["information_richness"] is F


def test_not_found_in_prose_is_not_blind():
    with pytest.raises(UnreadableAnswer) as exc:
        parse_answer("The skull's outline was not found in either rendering, sadly.", Q)
    assert exc.value.reason == "unreadable"
    with pytest.raises(UnreadableAnswer) as exc:
        parse_answer("The image was not found.", Q)
    assert exc.value.reason == "blind"
