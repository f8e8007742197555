"""Aspects as data: the built-in sets, intent mapping and user catalogues."""

from __future__ import annotations

import json

import numpy as np
import pytest

from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import (
    AspectError,
    aspects_for,
    aspects_for_intent,
    builtin_catalogue,
    load_aspects,
)


def test_builtin_sets_hold_the_paper_aspects():
    assert [a.key for a in aspects_for("quality")] == [
        "information_richness",
        "feature_discrimination",
        "color_content_harmony",
    ]
    assert [a.key for a in aspects_for("text")] == ["text_alignment"]
    assert [a.key for a in aspects_for("image")] == [
        "color_style_matching",
        "structural_style_matching",
    ]
    sketch = aspects_for("sketch")
    assert [(a.key, a.weight) for a in sketch] == [
        ("stroke_color_agreement", 2.0),
        ("unmarked_preservation", 1.0),
    ]
    edit = {a.key: a for a in aspects_for("edit")}
    assert edit["edit_instruction_alignment"].weight == 2.0
    assert "before the edit" in edit["structure_preservation"].description
    for a in builtin_catalogue().aspects.values():
        assert len(a.description) > 60, a.key


def test_intent_kinds_map_to_sets():
    img = np.zeros((4, 4, 3), np.uint8)
    assert aspects_for_intent(Intent()) == aspects_for("quality")
    assert aspects_for_intent(Intent(kind="text", text="red bone")) == aspects_for("text")
    assert aspects_for_intent(Intent(kind="image", reference=img)) == aspects_for("image")
    assert aspects_for_intent(Intent(kind="sketch")) == aspects_for("sketch")
    assert aspects_for_intent(Intent(kind="edit")) == aspects_for("edit")


def test_unknown_set_is_a_clear_error():
    with pytest.raises(AspectError) as exc:
        aspects_for("qualty")
    assert "qualty" in exc.value.message and "quality" in exc.value.hint


def test_user_file_adds_and_overrides(tmp_path):
    path = tmp_path / "mine.json"
    path.write_text(
        json.dumps(
            {
                "aspects": {
                    "vessel_visibility": {
                        "name": "Vessel visibility",
                        "description": "Thin vessels are visible and continuous.",
                        "weight": 3,
                    },
                    "text_alignment": {"name": "Follows the words", "description": "Reworded."},
                },
                "sets": {"text": ["text_alignment", {"key": "vessel_visibility", "weight": 0.5}]},
            }
        )
    )
    cat = load_aspects(path)
    text = cat.for_key("text")
    assert [(a.key, a.name, a.weight) for a in text] == [
        ("text_alignment", "Follows the words", 1.0),
        ("vessel_visibility", "Vessel visibility", 0.5),
    ]
    # The rest of the built-in catalogue is still there, and untouched.
    assert [a.key for a in cat.for_key("quality")] == [a.key for a in aspects_for("quality")]
    assert builtin_catalogue().get("text_alignment").name != "Follows the words"
    assert cat.get("vessel_visibility").weight == 3.0


@pytest.mark.parametrize(
    "content, words",
    [
        ("{not json", "not valid JSON"),
        (json.dumps({"aspects": {"x": {"name": "X"}}}), "non-empty name and description"),
        (json.dumps({"sets": {"quality": ["nope"]}}), "unknown aspect 'nope'"),
        (
            json.dumps({"aspects": {"bad key!": {"name": "a", "description": "b"}}}),
            "plain identifier",
        ),
        (json.dumps({"sets": {"text": []}}), "non-empty list"),
        (json.dumps([1, 2]), "not a JSON object"),
    ],
)
def test_bad_user_files_give_one_clear_error(tmp_path, content, words):
    path = tmp_path / "bad.json"
    path.write_text(content)
    with pytest.raises(AspectError) as exc:
        load_aspects(path)
    assert words in str(exc.value)


def test_missing_user_file(tmp_path):
    with pytest.raises(AspectError, match="does not exist"):
        load_aspects(tmp_path / "nowhere.json")
