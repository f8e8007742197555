"""MetricJudge: prefers what it can measure, ties on what it cannot, deterministic and cached."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from intuitf.evaluator.metric import MetricJudge, measure_for, named_colours
from intuitf.evaluator.types import Aspect, Choice, Intent, Judge

S = 96


def aspect(key: str, weight: float = 1.0) -> Aspect:
    return Aspect(key, key, key, weight)


QUALITY = [aspect("information_richness"), aspect("feature_discrimination")]


def disk(radius: float, cx: float = 0.5, cy: float = 0.5) -> np.ndarray:
    yy, xx = np.mgrid[0:S, 0:S] / S
    return (xx - cx) ** 2 + (yy - cy) ** 2 < radius**2


def canvas(bg=(0, 0, 0)) -> np.ndarray:
    img = np.zeros((S, S, 3), np.uint8)
    img[:] = bg
    return img


def paint(img: np.ndarray, mask: np.ndarray, rgb) -> np.ndarray:
    out = img.copy()
    out[mask] = rgb
    return out


def rich_image() -> np.ndarray:
    """Three coloured structures with shading, on black."""
    img = canvas()
    yy, xx = np.mgrid[0:S, 0:S] / S
    shade = (0.5 + 0.5 * xx)[..., None]
    for m, rgb in [
        (disk(0.4), (230, 220, 200)),
        (disk(0.2, 0.4, 0.4), (200, 40, 40)),
        (disk(0.12, 0.65, 0.6), (40, 80, 220)),
    ]:
        img[m] = (np.array(rgb) * shade[m]).astype(np.uint8)
    return img


def cmp(judge, a, b, aspects, intent=None):
    return asyncio.run(judge.compare(a, b, aspects, intent or Intent()))


def test_is_a_judge_and_deterministic():
    j = MetricJudge()
    assert isinstance(j, Judge) and j.name == "metric"
    a, b = rich_image(), paint(canvas(), disk(0.3), (200, 200, 200))
    v1 = cmp(j, a, b, QUALITY)
    v2 = cmp(MetricJudge(), a, b, QUALITY)
    assert v1.per_aspect == v2.per_aspect and v1.p_first == v2.p_first
    assert v1.cost.calls == 0


def test_quality_prefers_more_informative_rendering():
    j = MetricJudge()
    rich = rich_image()
    flat = paint(canvas(), disk(0.4), (200, 200, 200))
    empty = canvas()
    v = cmp(j, rich, flat, QUALITY)
    assert v.per_aspect["information_richness"] is Choice.FIRST
    assert v.per_aspect["feature_discrimination"] is Choice.FIRST
    assert v.overall is Choice.FIRST and v.p_first == 1.0
    # A flat disk carries next to no information (only its anti-aliased rim has other
    # colours), an empty image none; shading adds some.
    assert j.score(empty, "information_richness") == 0
    assert j.score(flat, "information_richness") < 0.2 * j.score(rich, "information_richness")
    shaded = rich.copy()
    shaded[disk(0.4)] = (rich[disk(0.4)].sum(axis=1, keepdims=True) // 3).astype(np.uint8)
    assert cmp(j, empty, shaded, QUALITY).overall is Choice.SECOND
    # Swapping the images swaps the verdict.
    assert cmp(j, flat, rich, QUALITY).overall is Choice.SECOND
    # A speck of varied colour does not beat a fully visible object.
    speck = canvas()
    speck[40:52, 40:52] = rich[::8, ::8]
    assert j.features(speck).variety > j.features(shaded).variety
    assert cmp(j, speck, shaded, [aspect("information_richness")]).overall is Choice.SECOND


def test_background_colour_does_not_count_as_content():
    j = MetricJudge()
    white_bg = paint(canvas((255, 255, 255)), disk(0.3), (200, 30, 30))
    black_bg = paint(canvas(), disk(0.3), (200, 30, 30))
    fw, fb = j.features(white_bg), j.features(black_bg)
    assert fw.coverage == pytest.approx(fb.coverage, abs=1e-9)
    assert fw.entropy == pytest.approx(fb.entropy, abs=1e-9)


def test_harmony_and_unknown_aspects_are_ties():
    j = MetricJudge()
    v = cmp(j, rich_image(), canvas(), [aspect("color_content_harmony"), aspect("realism")])
    assert v.per_aspect == {"color_content_harmony": Choice.TIE, "realism": Choice.TIE}
    assert v.overall is Choice.TIE and v.p_first == 0.5


def test_reference_prefers_closer_colours_and_structure():
    j = MetricJudge()
    ref = rich_image()
    near = np.clip(ref.astype(int) + 12, 0, 255).astype(np.uint8)
    near[~disk(0.4)] = 0
    far = paint(canvas(), disk(0.25, 0.3, 0.7), (40, 200, 60))
    intent = Intent(kind="image", reference=ref)
    aspects = [aspect("color_style_matching"), aspect("structural_style_matching")]
    v = cmp(j, far, near, aspects, intent)
    assert v.per_aspect == {k.key: Choice.SECOND for k in aspects}
    # A reference of another size is resized, not refused.
    big = np.kron(ref, np.ones((2, 2, 1), np.uint8))
    v = cmp(j, near, far, aspects, Intent(kind="image", reference=big))
    assert v.overall is Choice.FIRST


def test_a_reference_of_another_object_is_not_matched_by_an_empty_picture():
    """The reference shows one object (a faint red shell around bright ivory), the rendering
    another, elsewhere in the picture. Showing that object with the same faint shell and
    bright inside matches the reference's structure better than fading it out: SSIM over the
    whole picture, mostly the black around both objects, ranked the faded one higher (a head
    matched to a foot's picture lost its skin and skull over a long search)."""

    def shell_and_core(cx, cy, r, shell, core):
        img = paint(canvas(), disk(r, cx, cy), shell)
        return paint(img, disk(0.6 * r, cx, cy), core)

    ref = shell_and_core(0.3, 0.35, 0.18, (90, 20, 15), (235, 228, 205))
    shown = shell_and_core(0.65, 0.6, 0.25, (85, 22, 18), (230, 225, 200))
    faded = shell_and_core(0.65, 0.6, 0.25, (12, 3, 2), (30, 29, 26))
    j = MetricJudge()
    intent = Intent(kind="image", reference=ref)
    v = cmp(j, shown, faded, [aspect("structural_style_matching")], intent)
    assert v.overall is Choice.FIRST
    empty = canvas()
    assert j.score(empty, "structural_style_matching", intent) == 0.0
    # The same object in the same place still compares by its structure (SSIM): a copy of
    # the reference beats a shifted one.
    same = shell_and_core(0.3, 0.35, 0.18, (90, 20, 15), (235, 228, 205))
    moved = shell_and_core(0.36, 0.41, 0.18, (90, 20, 15), (235, 228, 205))
    assert cmp(j, same, moved, [aspect("structural_style_matching")], intent).overall is (
        Choice.FIRST
    )


def test_a_faint_colour_is_matched_by_its_hue_not_only_by_a_nearby_one():
    """A faint red layer that shows red beats one drifted towards orange: both lie within the
    30 degrees a faint colour may keep of its hue over a dark background, and counted alike
    there nothing held a faint skin's red over a long search."""
    j = MetricJudge()
    intent = Intent(kind="text", text="opaque white core and faint red skin")

    def layered(skin):
        # A thin shell (a seventh of the object), as a faint skin shows around a bone.
        return paint(paint(canvas(), disk(0.4), skin), disk(0.37), (240, 240, 240))

    red, orange_red = layered((105, 22, 20)), layered((105, 48, 14))
    v = cmp(j, red, orange_red, [aspect("text_alignment")], intent)
    assert v.overall is Choice.FIRST


def test_sketch_prefers_stroke_colours_and_preservation():
    j = MetricJudge()
    base = paint(paint(canvas(), disk(0.4), (220, 220, 210)), disk(0.15, 0.3, 0.3), (220, 220, 210))
    stroke = disk(0.1, 0.6, 0.6)
    sketch = np.zeros((S, S, 4), np.uint8)
    sketch[stroke] = (220, 30, 30, 255)
    good = paint(base, disk(0.14, 0.6, 0.6), (210, 40, 35))  # red under the stroke only
    spill = paint(base, disk(0.4), (210, 40, 35))  # red everywhere
    unchanged = base
    intent = Intent(kind="sketch", sketch=sketch, base=base)
    agree, keep = aspect("stroke_color_agreement", 2.0), aspect("unmarked_preservation")
    v = cmp(j, unchanged, good, [agree, keep], intent)
    assert v.per_aspect["stroke_color_agreement"] is Choice.SECOND
    v = cmp(j, spill, good, [agree, keep], intent)
    assert v.per_aspect["unmarked_preservation"] is Choice.SECOND
    assert v.overall is Choice.SECOND
    assert j.score(good, "stroke_color_agreement", intent) > -15.0  # mean ΔE under strokes


def test_sketch_shaded_stroke_colours_beat_one_bright_colour_for_both():
    """Red on the top, yellow below: a picture that shows both in their colours but shaded
    dark by the headlight meets the sketch; one that paints both bright yellow does not.
    (Measured plainly, dark red lay farther from the red stroke than yellow did, and a search
    on the tooth traded its red crown for yellow.)"""
    j = MetricJudge()
    top, low = disk(0.15, 0.5, 0.3), disk(0.15, 0.5, 0.7)
    base = paint(paint(canvas(), top, (200, 200, 200)), low, (200, 200, 200))
    sketch = np.zeros((S, S, 4), np.uint8)
    sketch[disk(0.08, 0.5, 0.3)] = (220, 30, 30, 255)
    sketch[disk(0.08, 0.5, 0.7)] = (240, 220, 40, 255)
    intent = Intent(kind="sketch", sketch=sketch, base=base)
    shaded = paint(paint(canvas(), top, (80, 10, 10)), low, (150, 110, 20))
    all_yellow = paint(paint(canvas(), top, (240, 220, 40)), low, (240, 220, 40))
    agree = [aspect("stroke_color_agreement")]
    assert cmp(j, all_yellow, shaded, agree, intent).overall is Choice.SECOND
    # Dark is not taken for any colour: grey where red was asked still misses.
    grey = paint(paint(canvas(), top, (80, 80, 80)), low, (150, 110, 20))
    assert cmp(j, grey, shaded, agree, intent).overall is Choice.SECOND


def test_sketch_a_hidden_stroked_structure_is_worse_than_a_wrong_colour():
    """Two strokes on two structures: a picture that hides the blue-stroked one loses to one
    that shows it in the other stroke's colour (black is nearer blue than yellow is, so a
    plain ΔE preferred hiding it)."""
    j = MetricJudge()
    top, root = disk(0.15, 0.5, 0.3), disk(0.15, 0.5, 0.7)
    base = paint(paint(canvas(), top, (200, 200, 200)), root, (200, 200, 200))
    sketch = np.zeros((S, S, 4), np.uint8)
    sketch[disk(0.08, 0.5, 0.3)] = (230, 210, 40, 255)  # yellow on the top
    sketch[disk(0.08, 0.5, 0.7)] = (30, 40, 230, 255)  # blue on the root
    intent = Intent(kind="sketch", sketch=sketch, base=base)
    yellow_top_gone_root = paint(canvas(), top, (230, 210, 40))
    both_yellow = paint(paint(canvas(), top, (230, 210, 40)), root, (230, 210, 40))
    agree = aspect("stroke_color_agreement")
    v = cmp(j, yellow_top_gone_root, both_yellow, [agree], intent)
    assert v.overall is Choice.SECOND
    # Without a base the judge cannot know a structure was there: plain ΔE decides.
    plain = Intent(kind="sketch", sketch=sketch)
    assert cmp(j, yellow_top_gone_root, both_yellow, [agree], plain).overall is Choice.FIRST


def test_text_named_colours_and_opacity_words():
    j = MetricJudge()
    text_aspect = [aspect("text_alignment")]
    red_blue = paint(paint(canvas(), disk(0.35), (220, 30, 30)), disk(0.15), (40, 80, 220))
    red_only = paint(canvas(), disk(0.35), (220, 30, 30))
    green = paint(canvas(), disk(0.35), (40, 170, 60))
    intent = Intent(kind="text", text="A tooth with red root and blue crown")
    assert cmp(j, red_only, red_blue, text_aspect, intent).overall is Choice.SECOND
    assert cmp(j, red_only, green, text_aspect, intent).overall is Choice.FIRST
    ivory = Intent(kind="text", text="opaque ivory bone")
    bone = paint(canvas(), disk(0.35), (248, 243, 222))
    faint_bone = paint(canvas(), disk(0.35), (70, 68, 62))
    assert cmp(j, faint_bone, bone, text_aspect, ivory).overall is Choice.SECOND
    faint = Intent(kind="text", text="a faint, transparent outline")
    assert cmp(j, faint_bone, bone, text_aspect, faint).overall is Choice.FIRST
    assert cmp(j, canvas(), faint_bone, text_aspect, faint).overall is Choice.SECOND
    # Nothing checkable in the text: a tie.
    style = Intent(kind="text", text="Studio Ghibli art style")
    assert cmp(j, red_only, green, text_aspect, style).overall is Choice.TIE


def test_named_colour_parsing():
    assert named_colours("Bone white skull, red teeth; RED again and light blue.") == [
        "bone white",
        "red",
        "light blue",
    ]
    assert named_colours("nothing here, not even redness") == []


def test_edit_with_region_and_instruction():
    j = MetricJudge()
    base = paint(paint(canvas(), disk(0.4), (220, 220, 210)), disk(0.12, 0.6, 0.6), (200, 200, 190))
    region = np.zeros((S, S, 4), np.uint8)
    region[disk(0.12, 0.6, 0.6)] = (0, 0, 0, 255)
    edited = paint(base, disk(0.12, 0.6, 0.6), (40, 80, 220))
    wrong_place = paint(base, disk(0.12, 0.3, 0.3), (40, 80, 220))
    aspects = [aspect("edit_instruction_alignment", 2.0), aspect("structure_preservation")]
    intent = Intent(kind="edit", text="make it blue", base=base, sketch=region)
    v = cmp(j, wrong_place, edited, aspects, intent)
    assert v.per_aspect == {a.key: Choice.SECOND for a in aspects}
    # Without a region and a colour the change is not checkable; preservation still is.
    vague = Intent(kind="edit", text="make it nicer", base=base)
    v = cmp(j, base, edited, aspects, vague)
    assert v.per_aspect["edit_instruction_alignment"] is Choice.TIE
    assert v.per_aspect["structure_preservation"] is Choice.FIRST


def test_keyword_fallback_for_user_aspects():
    assert measure_for("bone_structure_preservation", Intent()) == "preserve"
    assert measure_for("my_information_score", Intent()) == "richness"
    assert measure_for("plain_entropy", Intent()) == "entropy"  # the paper's baseline
    assert measure_for("depth_perception", Intent()) is None


def test_features_are_cached_by_content():
    j = MetricJudge(cache_size=2)
    a, b, c = rich_image(), canvas(), paint(canvas(), disk(0.2), (9, 9, 9))
    cmp(j, a, b, QUALITY)
    cmp(j, a.copy(), b, QUALITY)
    assert (j.cache_hits, j.cache_misses) == (2, 2)
    cmp(j, c, a, QUALITY)  # c evicts a (least recently used), then a evicts b
    assert (j.cache_hits, j.cache_misses) == (2, 4)
    cmp(j, c, a, QUALITY)
    assert (j.cache_hits, j.cache_misses) == (4, 4) and len(j._cache) == 2


def test_text_modifiers_apply_to_their_own_colour():
    """'opaque ivory bone, faint red skin': a faint red layer over solid ivory beats solid red."""
    from intuitf.evaluator.metric import MetricJudge
    from intuitf.evaluator.types import Choice, Intent
    from intuitf.intent.aspects import aspects_for

    yy, xx = np.mgrid[0:96, 0:96]
    body = (xx - 48) ** 2 + (yy - 48) ** 2 < 40**2
    bone = (xx - 48) ** 2 + (yy - 48) ** 2 < 18**2
    wanted = np.zeros((96, 96, 3), np.uint8)
    wanted[body] = (90, 20, 20)  # faint red: a translucent red layer over black
    wanted[bone] = (245, 240, 220)  # opaque ivory
    solid_red = np.zeros((96, 96, 3), np.uint8)
    solid_red[body] = (220, 40, 40)  # red skin hiding the bone
    intent = Intent(kind="text", text="opaque ivory bone, faint red skin")
    verdict = asyncio.run(MetricJudge().compare(wanted, solid_red, aspects_for("text"), intent))
    assert verdict.overall is Choice.FIRST
