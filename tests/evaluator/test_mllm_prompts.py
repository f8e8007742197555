"""Prompt text and image composition: deterministic, domain-neutral, labelled."""

from __future__ import annotations

import json

import numpy as np
import pytest

from intuitf.errors import JudgeError
from intuitf.evaluator.compose import (
    BEFORE_LABEL,
    FIRST_LABEL,
    PAIR_LABEL,
    REFERENCE_LABEL,
    SECOND_LABEL,
    SKETCH_LABEL,
    comparison_images,
    content_parts,
    decode_data_uri,
    side_by_side,
    sketch_overlay,
    split_side_by_side,
)
from intuitf.evaluator.prompts import SYSTEM_PROMPT, answer_schema, response_format, user_prompt
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for

RNG = np.random.default_rng(3)
A = RNG.integers(0, 256, (40, 50, 3), dtype=np.uint8)
B = RNG.integers(0, 256, (40, 50, 3), dtype=np.uint8)


def test_prompt_is_deterministic_and_lists_aspects():
    q = aspects_for("quality")
    p1, p2 = user_prompt(q, Intent()), user_prompt(q, Intent())
    assert p1 == p2
    for a in q:
        assert f"- [{a.key}] {a.name}: {a.description}" in p1
    assert '"first"' in p1 and '"second"' in p1 and '"cannot decide"' in p1
    # The schema in the text is the one sent as response_format.
    schema = json.loads(p1.split("follows this JSON schema:\n", 1)[1].split("\n", 1)[0])
    assert schema == response_format(q, Intent())["json_schema"]["schema"]


def test_no_assumed_domain_or_persona():
    q = aspects_for("quality")
    text = (SYSTEM_PROMPT + user_prompt(q, Intent())).lower()
    for word in ("radiologist", "ct scan", "patient", "medical", "you are a"):
        assert word not in text
    about = user_prompt(q, Intent(about="an industrial CT of an engine block"))
    assert "The volume is: an industrial CT of an engine block." in about


def test_intent_paragraphs():
    img = np.zeros((40, 50, 3), np.uint8)
    text = user_prompt(aspects_for("text"), Intent(kind="text", text="opaque ivory bone"))
    assert '"opaque ivory bone"' in text
    image = user_prompt(aspects_for("image"), Intent(kind="image", reference=img))
    assert "First interpret the reference" in image and "reference_description" in image
    assert (
        "reference_description"
        in answer_schema(aspects_for("image"), Intent(kind="image"))["required"]
    )
    assert (
        "reference_description"
        not in answer_schema(aspects_for("text"), Intent(kind="text"))["properties"]
    )
    edit = user_prompt(aspects_for("edit"), Intent(kind="edit", text="make it green", base=img))
    assert '"make it green"' in edit and "everything else should stay" in edit
    sketch = user_prompt(aspects_for("sketch"), Intent(kind="sketch"))
    assert "make the structure under this stroke this colour" in sketch


def test_schema_is_strict():
    s = answer_schema(aspects_for("quality"), Intent())
    asp = s["properties"]["aspects"]
    assert s["additionalProperties"] is False and asp["additionalProperties"] is False
    assert asp["required"] == [a.key for a in aspects_for("quality")]
    one = asp["properties"]["information_richness"]
    assert one["properties"]["choice"]["enum"] == ["first", "second", "cannot decide"]


def test_parts_layout_labels_and_roles():
    ref = np.full((30, 30, 3), 200, np.uint8)
    imgs = comparison_images(A, B, Intent(kind="image", reference=ref))
    assert [(i.role, i.label) for i in imgs] == [
        ("reference", REFERENCE_LABEL),
        ("first", FIRST_LABEL),
        ("second", SECOND_LABEL),
    ]
    parts = content_parts(imgs)
    assert [p["type"] for p in parts] == ["text", "image_url"] * 3
    assert parts[0]["text"] == REFERENCE_LABEL
    np.testing.assert_array_equal(decode_data_uri(parts[3]["image_url"]["url"]), A)  # PNG: exact
    yy, xx = np.mgrid[0:40, 0:50]
    smooth = np.stack([xx * 5, yy * 6, (xx + yy) * 2], -1).astype(np.uint8)
    jpeg = content_parts(comparison_images(smooth, B, Intent()), "jpeg", 90)[1]["image_url"]["url"]
    assert jpeg.startswith("data:image/jpeg;base64,")
    back = decode_data_uri(jpeg).astype(int)
    assert back.shape == smooth.shape and np.abs(back - smooth).mean() < 3  # quality 90


def test_edit_and_sketch_extra_parts():
    base = np.full((40, 50, 3), 100, np.uint8)
    strokes = np.zeros((40, 50, 4), np.uint8)
    strokes[10:20, 10:20] = (255, 0, 0, 255)
    sk = comparison_images(A, B, Intent(kind="sketch", sketch=strokes, base=base))
    assert sk[0].label == SKETCH_LABEL
    assert tuple(sk[0].image[15, 15]) == (255, 0, 0) and tuple(sk[0].image[30, 30]) == (
        100,
        100,
        100,
    )
    half = strokes.copy()
    half[..., 3] = 128
    assert abs(int(sketch_overlay(base, half)[15, 15, 0]) - 178) <= 1
    ed = comparison_images(A, B, Intent(kind="edit", text="x", base=base))
    assert ed[0].label == BEFORE_LABEL
    with pytest.raises(JudgeError, match="reference"):
        comparison_images(A, B, Intent(kind="image"))
    with pytest.raises(JudgeError, match="RGBA"):
        sketch_overlay(base, strokes[:10])


def test_side_by_side_round_trip():
    comp = side_by_side(A, B)
    imgs = comparison_images(A, B, Intent(), layout="side_by_side")
    assert len(imgs) == 1 and imgs[0].label == PAIR_LABEL
    a, b = split_side_by_side(comp)
    np.testing.assert_array_equal(a, A)
    np.testing.assert_array_equal(b, B)
    # The label band is not blank: the labels are drawn.
    assert (comp[:20] < 128).any()
    # Different heights: scaled to the smaller height.
    small = side_by_side(A, np.zeros((20, 25, 3), np.uint8))
    a2, b2 = split_side_by_side(small)
    assert a2.shape[0] == 20 and a2.shape[1] == b2.shape[1]
