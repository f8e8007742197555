"""A sketch's strokes grown over the structures they lie on, and judged there."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from helpers.strokes import BLOCKS_TF, sketch_over, two_blocks
from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.types import Intent
from intuitf.intent.regions import part_regions, sketch_regions
from intuitf.intent.strokes import stroke_regions, strokes_of
from intuitf.render import Camera, VolumeRenderer
from intuitf.tf import GaussianTF

CAM = Camera(azimuth=0.0, elevation=0.0)  # the 0.4 block on the left, the 0.8 on the right
SIZE = 64


def _silhouettes(vol, level: float = 0.5):
    """Where each block shows (alpha over ``level``; low: with its partial-volume rim)."""
    r = VolumeRenderer(vol, size=SIZE, shading=False)
    left = r.render_rgba(GaussianTF((BLOCKS_TF.gaussians[0],)), CAM)[..., 3] > level
    right = r.render_rgba(GaussianTF((BLOCKS_TF.gaussians[1],)), CAM)[..., 3] > level
    return left & ~right, right


def _ids_by_colour(sketch) -> dict[str, int]:
    return {
        ("red" if rgb[0] > rgb[2] else "blue"): k
        for k, (rgb, _) in enumerate(strokes_of(sketch, min_pixels=1), start=1)
    }


def test_each_stroke_grows_over_the_block_it_lies_on_and_no_further():
    vol = two_blocks()
    sketch = sketch_over(vol, CAM, SIZE)
    left, right = _silhouettes(vol)
    ids = stroke_regions(sketch, vol.data, vol.spacing, CAM, 0.1)
    assert ids is not None and ids.shape == (SIZE, SIZE)
    k = _ids_by_colour(sketch)
    drawn = sketch[..., 3] > 0
    # The strokes are five rows across each block; the regions are the blocks.
    assert (drawn & left).sum() < 0.3 * left.sum()
    assert ((ids == k["red"]) & left).sum() > 0.9 * left.sum()
    assert ((ids == k["blue"]) & right).sum() > 0.9 * right.sum()
    assert not ((ids == k["red"]) & right).any()
    assert not ((ids == k["blue"]) & left).any()
    # Where the rays meet nothing (beyond the blocks' one-pixel rims): no stroke's.
    assert not ids[~ndimage.binary_dilation(left | right)].any()


def test_one_stroke_has_nothing_to_be_told_apart_from():
    vol = two_blocks()
    sketch = sketch_over(vol, CAM, SIZE)
    red = sketch.copy()
    red[red[..., 2] > red[..., 0]] = 0  # the blue stroke rubbed out
    assert stroke_regions(red, vol.data, vol.spacing, CAM, 0.1) is None
    intent = Intent(kind="sketch", sketch=red, base=np.zeros((SIZE, SIZE, 3), np.uint8))
    assert part_regions(intent, vol, CAM, (SIZE, SIZE)) == ()


def test_a_big_sketch_is_grown_on_a_smaller_grid():
    vol = two_blocks()
    sketch = np.repeat(np.repeat(sketch_over(vol, CAM, SIZE), 4, axis=0), 4, axis=1)
    ids = stroke_regions(sketch, vol.data, vol.spacing, CAM, 0.1)
    assert ids is not None and ids.shape == (128, 128)


def _pictures(vol):
    """(right everywhere, right only on the strokes' rows): each block in its stroke's colour,
    or the left block red on its stroke's rows and blue elsewhere."""
    left, right = _silhouettes(vol, 0.01)
    good = np.zeros((SIZE, SIZE, 3), np.uint8)
    good[left], good[right] = (220, 30, 30), (40, 80, 220)
    lined = good.copy()
    rows = np.zeros((SIZE, SIZE), bool)
    rows[SIZE // 2 - 2 : SIZE // 2 + 3] = True
    lined[left & ~rows] = (40, 80, 220)
    return good, lined


def test_the_judge_checks_each_strokes_colour_over_its_whole_structure():
    vol = two_blocks()
    sketch = sketch_over(vol, CAM, SIZE)
    base = VolumeRenderer(vol, size=SIZE).render(BLOCKS_TF, CAM)
    plain = Intent(kind="sketch", sketch=sketch, base=base)
    regions = sketch_regions(plain, vol, CAM)
    assert [r.name for r in regions] == [f"{c} stroke" for c in _ids_by_colour(sketch)]
    intent = Intent(kind="sketch", sketch=sketch, base=base, part_regions=regions)
    good, lined = _pictures(vol)
    j = MetricJudge()
    # On the strokes' own pixels both pictures are right; over the blocks only one is.
    assert j.score(good, "stroke_color_agreement", plain) == j.score(
        lined, "stroke_color_agreement", plain
    )
    errors = j.stroke_errors(lined, intent)
    assert errors is not None and errors.max() > 20
    assert j.stroke_errors(good, intent).max() < 3
    assert j.score(good, "stroke_color_agreement", intent) > j.score(
        lined, "stroke_color_agreement", intent
    )


def test_a_structure_made_to_vanish_is_the_worst_error_of_its_region():
    vol = two_blocks()
    sketch = sketch_over(vol, CAM, SIZE)
    base = VolumeRenderer(vol, size=SIZE).render(BLOCKS_TF, CAM)
    plain = Intent(kind="sketch", sketch=sketch, base=base)
    intent = Intent(kind="sketch", sketch=sketch, base=base,
                    part_regions=sketch_regions(plain, vol, CAM))  # fmt: skip
    good, _ = _pictures(vol)
    left, _ = _silhouettes(vol, 0.01)
    gone = good.copy()
    gone[left] = 0
    errors = MetricJudge().stroke_errors(gone, intent)
    assert errors is not None and errors.max() > 100


def test_the_session_judges_a_sketch_over_its_strokes_regions():
    from intuitf.session import RunSettings, Session

    vol = two_blocks()
    sketch = sketch_over(vol, CAM, 48)
    base = VolumeRenderer(vol, size=48).render(BLOCKS_TF, CAM)
    settings = RunSettings(population=4, generations=1, image_size=48, output_size=48, seed=0,
                           camera=CAM.to_dict())  # fmt: skip
    intent = Intent(kind="sketch", sketch=sketch, base=base)
    with Session.create(vol, intent=intent, judge=MetricJudge(), settings=settings) as sess:
        judged = sess._judged_intent()
        assert len(judged.part_regions) == 2
        drawn = sketch[..., 3] > 0
        # Grown over the blocks: each region is larger than both strokes' lines together.
        assert all(r.mask.sum() > drawn.sum() for r in judged.part_regions)
        sess.step()
