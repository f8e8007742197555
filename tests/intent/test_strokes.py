"""Sketch strokes land on the structures under them (through the base picture's camera)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from helpers.strokes import sketch_over, two_blocks
from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.types import Intent
from intuitf.intent.hints import explorer_hints
from intuitf.intent.strokes import SEE_THROUGH, SEEN_BEHIND, VISIBLE, stroke_hints, strokes_of
from intuitf.render import Camera, VolumeRenderer
from intuitf.tf import Gaussian, GaussianTF
from intuitf.volume import Volume


def test_each_stroke_goes_to_the_values_under_it():
    vol = two_blocks()
    cam = Camera(azimuth=0.0, elevation=0.0)  # x to the right: the 0.4 block on the left
    sk = sketch_over(vol, cam)
    assert len(strokes_of(sk)) == 2
    got = {
        tuple(round(c, 2) for c in h.rgb): h
        for h in stroke_hints(sk, vol.data, vol.spacing, cam, 0.1)
    }
    red, blue = got[(0.86, 0.12, 0.12)], got[(0.16, 0.31, 0.86)]
    assert abs(red.center - 0.4) < 0.05 and abs(blue.center - 0.8) < 0.05
    assert red.hit_share > 0.9 and blue.hit_share > 0.9
    # Seen from the other side the same strokes land on the other block.
    back = Camera(azimuth=180.0, elevation=0.0)
    flipped = {tuple(round(c, 2) for c in h.rgb): h
               for h in stroke_hints(sk, vol.data, vol.spacing, back, 0.1)}  # fmt: skip
    assert abs(flipped[(0.86, 0.12, 0.12)].center - 0.8) < 0.05


def test_a_sketch_intent_gives_the_explorer_its_strokes():
    vol = two_blocks()
    cam = Camera(azimuth=0.0, elevation=0.0)
    sk = sketch_over(vol, cam)
    base = np.zeros((64, 64, 3), np.uint8)
    hints = explorer_hints(Intent(kind="sketch", sketch=sk, base=base), vol, camera=cam.to_dict())
    strokes = sorted((h for h in hints if h["name"] == "stroke"), key=lambda h: h["center"])
    assert len(strokes) == 2
    assert strokes[0]["color"][0] > 0.8 and strokes[1]["color"][2] > 0.8


def test_the_metric_judge_measures_each_stroke_alike():
    # A long red stroke all right and a short blue one all wrong lose to both mostly right:
    # the mean is taken per stroke, not per pixel (by pixels the short stroke would not count).
    sk = np.zeros((32, 32, 4), np.uint8)
    sk[5:25, 2:30] = (220, 30, 30, 255)  # long red
    sk[28:30, 2:6] = (40, 80, 220, 255)  # short blue
    base = np.zeros((32, 32, 3), np.uint8)
    intent = Intent(kind="sketch", sketch=sk, base=base)
    red_only = np.zeros((32, 32, 3), np.uint8)
    red_only[...] = (220, 30, 30)
    both = red_only.copy()
    both[20:32] = (40, 80, 220)  # a quarter of the red stroke wrong, the blue one right
    j = MetricJudge()
    assert j.score(both, "stroke_color_agreement", intent) > j.score(
        red_only, "stroke_color_agreement", intent
    )


def capped(skin: int = 2) -> tuple[Volume, np.ndarray, np.ndarray]:
    """A block whose upper half is solid 0.9 and whose lower half is 0.6 under a ``skin``
    voxels deep 0.9 skin (a tooth's enamel: thick on the crown, thin at its lower edge), and
    the masks (z, y, x) of the two halves."""
    d = np.full((40, 40, 40), 0.02, np.float32)
    upper = np.zeros(d.shape, bool)
    lower = np.zeros(d.shape, bool)
    # The camera below looks along y: the halves lie apart along z, the skin is across y.
    upper[21:30, 6:34, 10:30] = True
    lower[10:19, 6:34, 10:30] = True
    d[upper] = 0.9
    d[lower] = 0.9
    d[12:17, 6 + skin : 32, 12:28] = 0.6
    return Volume.from_array(d, value_range=(0.0, 1.0)), upper, lower


def red_and_yellow_over(vol: Volume, upper: np.ndarray, lower: np.ndarray):
    """The stroke hints of red drawn over the upper half and yellow over the lower one, seen
    along y: (red, yellow)."""
    cam = Camera(azimuth=0.0, elevation=0.0)
    size = 64
    r = VolumeRenderer(Volume.from_array(upper.astype(np.float32)), size=size, shading=False)
    tf = GaussianTF((Gaussian(1.0, 0.1, 0.8, (1, 1, 1)),))
    up = r.render_rgba(tf, cam)[..., 3] > 0.5
    r = VolumeRenderer(Volume.from_array(lower.astype(np.float32)), size=size, shading=False)
    low = r.render_rgba(tf, cam)[..., 3] > 0.5
    sk = np.zeros((size, size, 4), np.uint8)
    assert not (up & low).any()
    for mask, colour in ((up, (220, 30, 30)), (low, (240, 220, 40))):
        m = ndimage.binary_erosion(mask, iterations=3)
        assert m.sum() > 20
        sk[m, :3], sk[m, 3] = colour, 255
    got = {h.rgb[1] > 0.5: h for h in stroke_hints(sk, vol.data, vol.spacing, cam, 0.1)}
    return got[False], got[True]


def test_two_strokes_on_one_material_go_to_it_and_to_the_material_behind_the_thin_one():
    red, yellow = red_and_yellow_over(*capped())
    # Both strokes lie on 0.9: red keeps it, yellow means what its thin skin covers.
    assert abs(red.center - 0.9) < 0.03
    assert abs(yellow.center - 0.6) < 0.03
    # The cap stays red where thick and lets the yellow through where thin: translucent; the
    # yellow core is strong, as what shows of it is what the cap lets through.
    assert red.height == SEE_THROUGH and yellow.height == SEEN_BEHIND
    assert SEE_THROUGH[1] < VISIBLE[1] and SEEN_BEHIND[0] > SEE_THROUGH[1]
    # What became of each stroke is said in words a person can check.
    assert any("same material as the red stroke" in n for n in yellow.notes)
    assert any("translucent" in n and "yellow" in n for n in red.notes)


def test_the_translucent_stroke_keeps_to_the_values_only_the_thick_part_reaches():
    """Where the cap is thick a ray meets denser values than at its thin skin (the tooth's
    enamel: 0.90-0.92 on the cusps, 0.87-0.89 at its lower edge): the red stroke's Gaussian
    goes there, so the thin skin the yellow stroke looks through stays clear of it."""
    vol, upper, lower = capped()
    d = vol.data.copy()
    d[21:30, 8:34, 10:20] = 0.93  # half the cap is dense under its 0.9 face
    red, yellow = red_and_yellow_over(Volume.from_array(d, value_range=(0.0, 1.0)), upper, lower)
    assert abs(yellow.center - 0.6) < 0.03 and red.height == SEE_THROUGH
    assert abs(red.center - 0.93) < 0.01
    # The red Gaussian is all but gone at the thin skin's 0.9.
    assert np.exp(-0.5 * ((0.9 - red.center) / red.spread) ** 2) < 0.1


def test_the_material_behind_is_found_under_a_skin_as_deep_as_the_tooths_lower_enamel():
    """Seen obliquely, the enamel at the crown's middle is 8-10 voxels deep along a ray: the
    dentin behind it is still what the yellow stroke means."""
    red, yellow = red_and_yellow_over(*capped(skin=12))
    assert abs(yellow.center - 0.6) < 0.03 and yellow.height == SEEN_BEHIND
    assert abs(red.center - 0.9) < 0.03 and red.height == SEE_THROUGH


def test_a_strokes_edge_in_a_neighbouring_colour_bin_is_the_same_stroke():
    """A stroke drawn in #30a0ff has antialiased pixels at 47 beside 48 (another bin): they
    are its edge, not a second blue stroke competing with it for the same values."""
    sk = np.zeros((40, 40, 4), np.uint8)
    sk[10:14, 5:35] = (48, 160, 255, 255)
    sk[9, 5:35] = (47, 159, 250, 128)  # the edge, one bin lower
    sk[30:33, 5:35] = (139, 0, 0, 255)  # dark red
    sk[34:36, 5:35] = (220, 30, 30, 255)  # red: another stroke, though near dark red
    got = strokes_of(sk)
    assert len(got) == 3
    blue = next(mask for rgb, mask in got if rgb[2] > 200)
    assert blue.sum() == 4 * 30 + 30


def test_the_judge_counts_a_strokes_edge_with_its_stroke():
    """Each stroke counts alike in the judge's stroke measure; a stroke's antialiased edge in a
    neighbouring colour bin is part of it, not a stroke of its own that weighs as much."""
    sk = np.zeros((40, 40, 4), np.uint8)
    sk[10:14, 5:35] = (48, 160, 255, 255)
    sk[9, 5:35] = (47, 159, 250, 128)
    img = np.zeros((40, 40, 3), np.uint8)
    img[10:14, 5:35] = (48, 160, 255)  # the stroke met; its one-pixel edge shows black
    judge = MetricJudge()
    score = judge._stroke(judge.features(img), Intent(kind="sketch", sketch=sk))
    # The edge is a fifth of the stroke's pixels: about a fifth of black's distance, not half.
    black = float(np.linalg.norm(judge.features(img).lab[10, 10] - judge.features(img).lab[0, 0]))
    assert -0.3 * black < score < -0.1 * black
