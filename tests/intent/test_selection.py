"""Where an edit should happen: the selection mask, and a model judge that is shown it."""

from __future__ import annotations

import asyncio
from dataclasses import replace

import numpy as np
import pytest

from intuitf.evaluator.compose import BEFORE_LABEL, SELECTION_LABEL, comparison_images
from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.prompts import user_prompt
from intuitf.evaluator.types import Choice, Intent
from intuitf.intent.aspects import aspects_for
from intuitf.intent.selection import outline_selection, selection_mask
from intuitf.testing.fake_mllm import FakeMLLMServer

S = 64


def disk(r, cx=0.5, cy=0.5):
    yy, xx = np.mgrid[0:S, 0:S] / S
    return (xx - cx) ** 2 + (yy - cy) ** 2 < r**2


def test_mask_from_attribution():
    attr = np.zeros((3, S, S), np.float32)
    attr[0][disk(0.4)] = 0.5  # a faint shell over everything
    attr[2][disk(0.15, 0.6, 0.6)] = 0.45  # the selected feature
    attr[1][disk(0.1, 0.3, 0.3)] = 0.4
    m = selection_mask(attr, [2])
    assert m.shape == (S, S) and m.dtype == bool
    inside = disk(0.13, 0.6, 0.6)
    assert m[inside].mean() > 0.95
    assert not m[disk(0.1, 0.3, 0.3)].any() and not m[~disk(0.4)].any()
    # Several selected features: their union.
    assert selection_mask(attr, [1, 2])[disk(0.08, 0.3, 0.3)].all()
    with pytest.raises(ValueError):
        selection_mask(attr, [3])


def test_outline_marks_the_selection_and_dims_the_rest():
    base = np.full((S, S, 3), 200, np.uint8)
    m = disk(0.2)
    out = outline_selection(base, m)
    assert (out[m] == 200).all()
    ring = np.argwhere(~m & np.roll(m, 2, axis=1))
    assert ring.size and tuple(out[tuple(ring[0])]) == (255, 0, 255)
    far = ~disk(0.35)
    assert (out[far] < 120).all()
    # A mask of another size is fitted to the picture.
    big = np.kron(m, np.ones((2, 2), bool))
    assert outline_selection(base, big).shape == base.shape


def _edit_pictures():
    base = np.zeros((S, S, 3), np.uint8)
    base[disk(0.4)] = (90, 30, 30)  # faint red skin
    base[disk(0.15, 0.6, 0.6)] = (240, 235, 220)  # the crown, ivory
    mask = disk(0.15, 0.6, 0.6)
    gold = base.copy()
    gold[mask] = (212, 175, 55)
    spilt = gold.copy()
    spilt[disk(0.4) & ~mask] = (160, 130, 40)  # gold everywhere
    return base, mask, gold, spilt


def test_metric_judge_measures_the_edit_in_the_selection():
    base, mask, gold, spilt = _edit_pictures()
    intent = Intent(kind="edit", text="make the crown gold", base=base, selected=(2,),
                    selection_mask=mask)  # fmt: skip
    edit = aspects_for("edit")
    j = MetricJudge()
    v = asyncio.run(j.compare(base, gold, edit, intent))
    assert v.per_aspect["edit_instruction_alignment"] is Choice.SECOND
    assert v.overall is Choice.SECOND  # the unchanged base no longer wins
    v = asyncio.run(j.compare(spilt, gold, edit, intent))
    assert v.per_aspect["structure_preservation"] is Choice.SECOND
    assert v.overall is Choice.SECOND
    # Each step toward the colour counts (no plateau at zero).
    half = base.copy()
    half[mask] = (226, 205, 138)
    assert (
        j.score(base, "edit_instruction_alignment", intent)
        < j.score(half, "edit_instruction_alignment", intent)
        < j.score(gold, "edit_instruction_alignment", intent)
    )
    # Opacity words: "more transparent" prefers the selection fading toward the background.
    faded = base.copy()
    faded[mask] = (110, 108, 100)
    fade = Intent(kind="edit", text="make it more transparent", base=base, selection_mask=mask)
    assert (
        asyncio.run(j.compare(base, faded, edit, fade)).per_aspect["edit_instruction_alignment"]
        is Choice.SECOND
    )


def test_transparent_is_done_once_see_through_and_then_the_rest_decides():
    # The selected crown fades: to under half its contrast with the background (see-through),
    # or to nothing while the skin next to it, which shares its values, fades too.
    base, mask, _, _ = _edit_pictures()
    see_through = base.copy()
    see_through[mask] = (106, 103, 97)
    wiped = base.copy()
    wiped[mask] = 0
    wiped[disk(0.4) & ~disk(0.2, 0.6, 0.6)] = (60, 20, 20)
    edit = aspects_for("edit")
    j = MetricJudge()
    fade = Intent(kind="edit", text="transparent", base=base, selection_mask=mask)
    v = asyncio.run(j.compare(see_through, wiped, edit, fade))
    assert v.per_aspect["edit_instruction_alignment"] is Choice.TIE
    assert v.overall is Choice.FIRST
    # Short of see-through, fading further still counts.
    faint = base.copy()
    faint[mask] = (190, 186, 175)
    v = asyncio.run(j.compare(faint, see_through, edit, fade))
    assert v.per_aspect["edit_instruction_alignment"] is Choice.SECOND
    # "hide" asks for it gone: all the way counts.
    hide = Intent(kind="edit", text="hide it", base=base, selection_mask=mask)
    v = asyncio.run(j.compare(see_through, wiped, edit, hide))
    assert v.per_aspect["edit_instruction_alignment"] is Choice.SECOND


def test_the_selection_is_part_of_the_intent_fingerprint():
    base, mask, _, _ = _edit_pictures()
    a = Intent(kind="edit", text="gold", base=base, selection_mask=mask)
    b = Intent(kind="edit", text="gold", base=base, selection_mask=np.roll(mask, 3, axis=0))
    c = Intent(kind="edit", text="gold", base=base)
    assert len({a.fingerprint(), b.fingerprint(), c.fingerprint()}) == 3


def test_a_model_judge_is_shown_the_selection(monkeypatch):
    base, mask, gold, _ = _edit_pictures()
    intent = Intent(kind="edit", text="make this gold", base=base, selected=(2,),
                    selection_mask=mask)  # fmt: skip
    parts = comparison_images(gold, base, intent)
    assert [p.role for p in parts] == ["before", "selection", "first", "second"]
    assert parts[0].label == BEFORE_LABEL and parts[1].label == SELECTION_LABEL
    assert "'Selection'" in user_prompt(aspects_for("edit"), intent)
    # Without a mask nothing changes.
    plain = Intent(kind="edit", text="make this gold", base=base, selected=(2,))
    assert [p.role for p in comparison_images(gold, base, plain)] == ["before", "first", "second"]
    assert "'Selection'" not in user_prompt(aspects_for("edit"), plain)

    # Over HTTP, the request the model gets carries the outlined picture after its label.
    sent: list[list[dict]] = []
    original = MLLMJudge._complete

    async def spy(self, messages, *args, **kwargs):
        sent.append(messages)
        return await original(self, messages, *args, **kwargs)

    monkeypatch.setattr(MLLMJudge, "_complete", spy)
    with FakeMLLMServer(target=gold) as srv:
        judge = MLLMJudge("default", base_url=srv.base_url, swap="never")

        async def ask():
            try:
                return await judge.compare(gold, base, aspects_for("edit"), intent)
            finally:
                await judge.aclose()

        v = asyncio.run(ask())
    assert v.error is None and v.overall is Choice.FIRST
    content = sent[0][1]["content"]
    texts = [p["text"] for p in content if p["type"] == "text"]
    assert SELECTION_LABEL in texts
    k = next(i for i, p in enumerate(content) if p.get("text") == SELECTION_LABEL)
    assert content[k + 1]["type"] == "image_url"
    assert content[k + 1]["image_url"]["url"].startswith("data:image/png;base64,")


def _pot_over_soil():
    """A dark brown pot (selected) in front of bright silver soil, over a black background."""
    mask = disk(0.25)
    base = np.zeros((S, S, 3), np.uint8)
    base[mask] = (90, 50, 30)
    behind = np.zeros((S, S, 3), np.uint8)
    behind[mask] = (200, 200, 205)  # the soil the pot covers
    see_through = base.copy()
    see_through[mask] = (150, 128, 118)  # half-way: the soil shows through the pot
    darker = base.copy()
    darker[mask] = (55, 30, 18)  # nearer the background, but the pot only grew denser
    return base, behind, mask, see_through, darker


def test_transparent_fades_toward_what_the_selection_covers_not_the_background():
    # Fading a pot shows the soil in it, which stands out more from the black background than
    # the pot did: judged against the background, a darker, denser pot looked "more
    # transparent" and the refine kept the pot as it was.
    base, behind, mask, see_through, darker = _pot_over_soil()
    edit = aspects_for("edit")
    j = MetricJudge()
    fade = Intent(kind="edit", text="transparent", base=base, selected=(3,),
                  selection_mask=mask, behind=behind)  # fmt: skip
    v = asyncio.run(j.compare(darker, see_through, edit, fade))
    assert v.per_aspect["edit_instruction_alignment"] is Choice.SECOND
    assert v.overall is Choice.SECOND
    # "more opaque" goes the other way: away from what the selection covers.
    solid = replace(fade, text="more opaque")
    v = asyncio.run(j.compare(darker, see_through, edit, solid))
    assert v.per_aspect["edit_instruction_alignment"] is Choice.FIRST
    # Without the picture behind, the background stands in (what lies behind is unknown).
    assert fade.fingerprint() == replace(fade, behind=None).fingerprint()


def test_the_session_renders_what_the_selected_features_cover():
    from intuitf.intent.selection import edit_intent
    from intuitf.render import Camera, VolumeRenderer
    from intuitf.session import RunSettings
    from intuitf.tf import Gaussian, GaussianTF
    from intuitf.volume import Volume

    z, y, x = np.mgrid[0:32, 0:32, 0:32] / 31.0 - 0.5
    r = np.sqrt(x**2 + y**2 + z**2)
    data = np.where(r < 0.2, 0.8, np.where(r < 0.35, 0.4, 0.02)).astype(np.float32)
    vol = Volume.from_array(data, value_range=(0.0, 1.0))
    tf = GaussianTF((Gaussian(0.4, 0.03, 0.3, (0.45, 0.25, 0.1)),
                     Gaussian(0.8, 0.03, 0.9, (0.9, 0.9, 0.95))))  # fmt: skip
    settings = RunSettings(image_size=48, output_size=48, shading=False)
    got = edit_intent(Intent(kind="edit", text="transparent", selected=(0,)), vol, tf, settings)
    cache = VolumeRenderer(vol, size=48, shading=False).sample_cache(Camera())
    assert np.array_equal(got.base, cache.render(tf))
    assert np.array_equal(got.behind, cache.render(tf.hide((0,))))
    assert tf.hide((0,)).gaussians[0].height == 0.0
    # Behind the shell lies the bright core: there the picture without it is brighter.
    core = got.selection_mask & (got.behind.mean(axis=2) > got.base.mean(axis=2) + 20)
    assert core.sum() > 20
    # A resumed run reads its base back: the same picture, so the same picture behind it; a
    # base from another view gets none (what lies behind it there is not known).
    again = edit_intent(replace(got, selection_mask=None, behind=None), vol, tf, settings)
    assert np.array_equal(again.behind, got.behind)
    other = np.zeros_like(got.base)
    given = Intent(kind="edit", text="transparent", selected=(0,), base=other)
    assert edit_intent(given, vol, tf, settings).behind is None
