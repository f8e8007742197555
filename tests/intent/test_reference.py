"""A reference picture read as layers (outline and inside), placed on another volume's
structures, and judged by where its colours are."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.types import Intent
from intuitf.intent.hints import _Layout, _materials, explorer_hints, intent_hints
from intuitf.intent.parts import match_parts
from intuitf.intent.reference import reference_layers, reference_words
from intuitf.intent.structures import build_structure_map
from intuitf.render import Camera, VolumeRenderer
from intuitf.tf import Gaussian, GaussianTF
from intuitf.volume import load_volume


def _disc(outline_rgb, inside_rgb, size=96) -> np.ndarray:
    """A dark picture with a disc: a ring of ``outline_rgb`` around ``inside_rgb``."""
    yy, xx = np.mgrid[:size, :size]
    r = np.hypot(yy - size / 2, xx - size / 2)
    img = np.zeros((size, size, 3), np.uint8)
    img[r < 36] = outline_rgb
    img[r < 30] = inside_rgb
    return img


def test_a_dim_red_outline_around_ivory_reads_as_faint_red_skin_over_opaque_ivory():
    layers = reference_layers(_disc((70, 12, 12), (240, 232, 210)))
    assert [(k, look) for k, _, look in layers] == [("outer", "faint"), ("inner", "opaque")]
    outer, inner = (np.array(rgb) for _, rgb, _ in layers)
    # Brightened back from the dimming: a red, not a dark red.
    assert outer[0] > 0.9 and outer[1] < 0.25 and outer[2] < 0.25
    assert inner.min() > 0.8
    words = reference_words(layers)
    assert words.startswith("faint red outer part and opaque ")
    assert "bone" not in words  # "bone white" would read as a material


def test_layers_seen_through_each_other_are_read_as_their_own_colours():
    """A faint red skin lies in front of the ivory bone, so the inside shows pink where the skin
    is thick and nearly ivory where it is thin, and the outline band takes in bone too. Read as
    the band's and the inside's means, the layers came out salmon and pinkish ivory, and a
    search steered by them made pink skulls (a foot rendered from its labels read as (0.95,
    0.47, 0.44) over (0.95, 0.82, 0.76))."""
    size = 96
    yy, xx = np.mgrid[:size, :size]
    r = np.hypot(yy - size / 2, xx - size / 2)
    red, ivory = np.array([0.86, 0.12, 0.12]), np.array([0.98, 0.96, 0.88])
    img = np.zeros((size, size, 3))
    img[r < 40] = 0.3 * red  # the skin alone, dimmed by its opacity
    # The bone, off centre so that it reaches into the outline band on one side, seen through
    # skin whose share grows from 0.05 to 0.5 across it.
    bone = np.hypot(yy - size / 2, xx - size / 2 - 7) < 32
    share = 0.05 + 0.45 * (xx - xx[bone].min()) / np.ptp(xx[bone])
    img[bone] = share[bone, None] * red + (1 - share[bone, None]) * ivory
    layers = reference_layers((img * 255).astype(np.uint8))
    assert [(k, look) for k, _, look in layers] == [("outer", "faint"), ("inner", "opaque")]
    outer, inner = (np.array(rgb) for _, rgb, _ in layers)
    assert outer[0] > 0.9 and outer[1] < 0.2 and outer[2] < 0.2  # red, not salmon
    # Near ivory: nearly as green as red (the pink mixtures fall short in green), no bluer.
    assert inner[1] > 0.85 * inner[0] and inner[2] < inner[1]


def test_one_colour_or_no_object_says_nothing_about_layers():
    assert reference_layers(_disc((200, 200, 190), (205, 200, 192))) == []
    assert reference_layers(np.zeros((64, 64, 3), np.uint8)) == []
    # A bright outline is no faint one.
    layers = reference_layers(_disc((40, 200, 60), (240, 232, 210)))
    assert [look for _, _, look in layers] == [None, "opaque"]


@pytest.fixture(scope="module")
def foot_picture(data_dir) -> np.ndarray:
    """The foot as a radiologist sets it up: faint red skin, opaque ivory bone."""
    foot = load_volume(data_dir / "foot_zfp8lossy_256x256x256_uint8.raw.gz", max_dim=64)
    tf = GaussianTF(
        (
            Gaussian(0.15, 0.06, 0.02, (0.86, 0.12, 0.12)),
            Gaussian(0.6, 0.1, 0.9, (0.98, 0.96, 0.88)),
        )
    )
    return VolumeRenderer(foot, size=96).render(tf, Camera(azimuth=30.0, elevation=20.0))


@pytest.fixture(scope="module")
def head(data_dir):
    return load_volume(data_dir / "ctheadstanford_256x256x113_uint16.raw.gz", max_dim=64)


def test_the_foot_as_reference_puts_faint_red_on_the_heads_skin_and_ivory_on_its_skull(
    foot_picture, head
):
    th = intent_hints(Intent(kind="image", reference=foot_picture), head)
    by = {h.material: h for h in th.hints}
    assert set(by) == {"outer part", "inner part"}
    assert "from the reference picture" in th.summary()
    outer, inner = by["outer part"], by["inner part"]
    assert outer.opacity == "faint" and inner.opacity == "opaque"
    # The picture's own colours, not their nearest names.
    assert outer.rgb[0] > 0.8 and outer.rgb[1] < 0.4
    # Ivory seen through faint red skin: light and warm, far less red than the outline.
    assert min(inner.rgb) > 0.6 and inner.rgb[1] / inner.rgb[0] > 0.7
    smap = build_structure_map(head.data, head.histogram()[0], tuple(head.spacing))
    fg = smap.foreground()
    # Faint red on the soft tissue around everything (most of the head), ivory on what is
    # denser than it (the skull).
    bulk = max(fg, key=lambda s: s.share)
    assert outer.structure == bulk.id and bulk.share > 0.5
    denser = [s for s in fg if s.center > bulk.center]
    lo = min(s.value_range[0] for s in denser)
    assert lo <= inner.center <= max(s.value_range[1] for s in denser)
    assert outer.center + 2 * outer.spread < lo


def test_a_text_wins_over_the_picture(foot_picture, head):
    th = intent_hints(Intent(kind="image", reference=foot_picture, text="opaque blue bone"), head)
    assert [h.material for h in th.hints] == ["bone"]


@pytest.fixture(scope="module")
def chest(data_dir):
    # At 96 the map holds specks of partial volume with the lowest values.
    return load_volume(data_dir / "chestlidc2_256x256x133_uint8.raw.gz", max_dim=96)


def test_a_speck_is_never_the_layer_around_the_body(chest):
    smap = build_structure_map(chest.data, chest.histogram()[0], tuple(chest.spacing))
    fg = smap.foreground()
    outer = match_parts(["outer"], smap)["outer"]
    skin = match_parts(["skin"], smap)["skin"]
    biggest_low = max((s for s in fg if s.share >= 0.05), key=lambda s: -s.center)
    assert outer.id == skin.id == biggest_low.id
    assert outer.share >= 0.05 > min(s.share for s in fg)  # there are specks to avoid


def test_a_faint_outer_layer_keeps_its_tail_off_the_background(chest):
    hints = explorer_hints(Intent(kind="text", text="faint red outer part"), chest)
    outer = next(h for h in hints if h["name"] == "outer part")
    counts = np.asarray(chest.histogram()[0], np.float64)
    cutoff = _Layout.of(counts, _materials(counts)).cutoff
    assert outer["center"] - 2.5 * outer["spread"] >= cutoff - 1e-9
    bg = [h for h in hints if h["name"] == "background"]
    assert len(bg) == 1 and bg[0]["hidden"]


def test_the_judge_prefers_the_reference_colours_where_the_reference_has_them(foot_picture, head):
    """A head with faint red skin over an ivory skull against one with the same colours
    swapped into an opaque ivory skin (no skull): the first matches the foot's style."""
    cam = Camera(azimuth=0.0, elevation=10.0, roll=180.0)
    r = VolumeRenderer(head, size=96)
    layered = r.render(
        GaussianTF(
            (
                Gaussian(0.34, 0.03, 0.01, (0.86, 0.12, 0.12)),
                Gaussian(0.62, 0.05, 0.9, (0.98, 0.96, 0.88)),
            )
        ),
        cam,
    )
    shell = r.render(
        GaussianTF(
            (
                Gaussian(0.34, 0.03, 0.6, (0.98, 0.96, 0.88)),
                Gaussian(0.62, 0.05, 0.02, (0.86, 0.12, 0.12)),
            )
        ),
        cam,
    )
    judge = MetricJudge()
    intent = Intent(kind="image", reference=foot_picture)
    assert judge.score(layered, "color_style_matching", intent) > judge.score(
        shell, "color_style_matching", intent
    )


def test_a_reference_layer_faded_out_of_its_structure_fails_the_style(foot_picture, head):
    """The foot's faint red skin, read onto the head: where the head's skin alone lies on
    the ray (around the skull) it must show red at all. Faded to a trace of another hue, the
    head's picture still has the foot's ivory outline (its skull's edge) and much of its
    colour histogram: with the metric judge, the head's skin faded out over a search."""
    from intuitf.evaluator.metric import REF_REGION_WEIGHT
    from intuitf.intent.regions import part_regions
    from intuitf.session.building import default_camera

    cam = Camera.from_dict(default_camera(head))
    plain = Intent(kind="image", reference=foot_picture)
    regions = part_regions(plain, head, cam, (96, 96))
    assert [r.name for r in regions] == ["outer part"] and regions[0].look == "faint"
    told = Intent(kind="image", reference=foot_picture, part_regions=regions)
    skull = Gaussian(0.575, 0.022, 0.45, (0.99, 0.96, 0.86))
    r = VolumeRenderer(head, size=96)
    faded = r.render(GaussianTF((Gaussian(0.34, 0.07, 0.004, (0.94, 0.66, 0.49)), skull)), cam)
    red = r.render(GaussianTF((Gaussian(0.34, 0.07, 0.01, (0.95, 0.35, 0.25)), skull)), cam)
    judge = MetricJudge()

    def style(img, intent):
        return judge.score(img, "color_style_matching", intent)

    # The layer shown in its hue loses nothing to the check; faded out, it loses.
    assert style(red, told) == pytest.approx(style(red, plain))
    assert style(faded, told) == pytest.approx(style(faded, plain) - REF_REGION_WEIGHT)
    assert style(red, told) > style(faded, told)
