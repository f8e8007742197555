"""A sketch's strokes are fitted: the first generation holds a TF that shows them."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.strokes import BLOCKS_TF, sketch_over, two_blocks
from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.types import Intent, PartRegion
from intuitf.intent.sketch_fit import fit_sketch, material_errors, regions_on
from intuitf.intent.strokes import StrokeHint
from intuitf.render import Camera, VolumeRenderer
from intuitf.session import RunDirectory, Session
from intuitf.session.settings import RunSettings

CAM = Camera(azimuth=0.0, elevation=0.0)  # the 0.4 block on the left, the 0.8 on the right
RED, BLUE = (220 / 255, 30 / 255, 30 / 255), (40 / 255, 80 / 255, 220 / 255)


def _sketch_intent(vol, size: int = 64) -> Intent:
    base = VolumeRenderer(vol, size=size).render(BLOCKS_TF, CAM)
    return Intent(kind="sketch", sketch=sketch_over(vol, CAM, size), base=base)


def test_the_fit_moves_a_stroke_gaussian_onto_the_values_that_show_it():
    vol = two_blocks()
    intent = _sketch_intent(vol)
    view = VolumeRenderer(vol, size=64).sample_cache(CAM)
    judge = MetricJudge()
    # The red stroke's hint placed off its block's value (0.40), above it and too narrow to
    # reach it: the left block shows nothing, its stroke's error is the worst there is. (Below
    # it, the segments from the air into the block would cross it: pre-integrated, a shell.)
    strokes = [
        StrokeHint(RED, 100, 0.47, 0.01, 1.0, (0.05, 0.8)),
        StrokeHint(BLUE, 100, 0.80, 0.02, 1.0, (0.05, 0.8)),
    ]
    fit = fit_sketch(strokes, lambda tf: judge.stroke_errors(view.render(tf), intent), seed=0)
    assert fit is not None and fit.improved
    assert max(fit.before) > 100  # the red block hidden
    assert max(fit.after) < 20, fit.after
    red = next(g for g in fit.tf.gaussians if g.color[0] > 0.8)
    # Its Gaussian now reaches the 0.4 block (within two widths), in the stroke's colour.
    assert abs(red.mean - 0.4) < 2 * red.width + 0.01, red
    assert red.color == RED


def test_nothing_to_fit_gives_no_fit():
    assert fit_sketch([], lambda tf: np.array([1.0])) is None
    hint = StrokeHint(RED, 10, 0.4, 0.02, 1.0)
    assert fit_sketch([hint], lambda tf: None) is None


def test_a_search_that_stalls_starts_again_and_spends_its_whole_budget():
    # A cost that no step changes stalls CMA-ES at once (flat fitness): the fit then starts
    # again from its best point until its iterations are spent, instead of stopping there.
    hint = StrokeHint(RED, 10, 0.4, 0.02, 1.0)
    fit = fit_sketch([hint], lambda tf: np.array([5.0]), iterations=12, popsize=4)
    assert fit is not None
    assert fit.evaluations == 1 + 12 * 4


def test_the_stroke_errors_of_a_fresh_picture_are_those_of_a_judged_one():
    # Measured on the pixels alone (a fit's pictures) or on the judge's cached features (a
    # run's candidates), a picture's stroke errors are the same.
    vol = two_blocks()
    intent = _sketch_intent(vol)
    picture = VolumeRenderer(vol, size=64).render(BLOCKS_TF, CAM)
    judged = MetricJudge()
    judged.features(picture)
    cached = judged.stroke_errors(picture, intent)
    fresh = MetricJudge().stroke_errors(picture, intent)
    assert cached is not None and fresh is not None
    np.testing.assert_allclose(cached, fresh)
    assert cached.max() > 0.0


def test_a_regions_material_colour_is_its_rays_colour_however_faint():
    # Premultiplied RGBA: the left half yellow, faint at the top and opaque below; the right
    # half red over the region's bottom rows, yellow above.
    yellow, red = np.array([0.94, 0.86, 0.16]), np.array([0.86, 0.12, 0.12])
    rgba = np.zeros((8, 8, 4), np.float32)
    alpha = np.where(np.arange(8)[:, None] < 4, 0.05, 0.9)[:, :4]
    rgba[:, :4, :3] = yellow * alpha[..., None]
    rgba[:, :4, 3] = alpha
    rgba[:4, 4:, :3], rgba[:4, 4:, 3] = yellow * 0.5, 0.5
    rgba[4:, 4:, :3], rgba[4:, 4:, 3] = red * 0.5, 0.5
    left, right, empty = (np.zeros((8, 8), bool) for _ in range(3))
    left[:, :4], right[:, 4:] = True, True
    regions = [PartRegion("left", tuple(yellow), left), PartRegion("right", tuple(yellow), right),
               PartRegion("empty", tuple(yellow), empty)]  # fmt: skip
    errors = material_errors(rgba, regions)
    assert errors[0] < 0.5  # its faint and its opaque rays alike: yellow
    assert errors[1] > 15.0  # half of it red
    assert errors[2] == 100.0  # nothing there takes a colour


def test_regions_are_resized_to_the_picture_they_are_measured_on():
    mask = np.zeros((16, 16), bool)
    mask[:8] = True
    region = PartRegion("top", (1.0, 0.0, 0.0), mask)
    with pytest.raises(ValueError, match="regions_on"):
        material_errors(np.zeros((8, 8, 4), np.float32), [region])
    (small,) = regions_on([region], (8, 8))
    assert small.mask.shape == (8, 8) and small.mask[:4].all() and not small.mask[4:].any()


SMALL = dict(population=6, generations=2, image_size=48, output_size=48, top_k=1)


def test_a_sketch_run_starts_at_the_strokes_with_the_fitted_tf_in_its_first_generation(tmp_path):
    vol = two_blocks()
    intent = _sketch_intent(vol, 48)
    settings = RunSettings(**SMALL, camera=CAM.to_dict())
    with Session.create(vol, intent=intent, settings=settings, run_dir=tmp_path / "run") as s:
        assert s.plan == [("customize", 2)]  # no quality-only stage before the strokes
        first = s.explorer.ask()
        assert any(c.tf.name == "fitted to the sketch" for c in first)
        line = next(x for x in s.understood if "fitted to the strokes" in x)
        assert "red " in line and "blue " in line  # each stroke by its colour, before → after
    record = RunDirectory(tmp_path / "run").read_run()
    fit = record["sketch_fit"]
    assert max(fit["after"]) <= max(fit["before"])
    assert record["plan"] == [["customize", 2]]
    # Without the fit the run keeps its quality-only first stage and no fitted TF.
    off = RunSettings(**SMALL, camera=CAM.to_dict(), fit_sketch=False)
    with Session.create(vol, intent=intent, settings=off) as s:
        assert s.plan[0][0] == "initialize"
        assert not any(c.tf.name == "fitted to the sketch" for c in s.explorer.ask())


def test_a_sketch_asked_during_a_run_brings_its_fitted_tf_into_the_population():
    vol = two_blocks()
    intent = _sketch_intent(vol, 48)
    settings = RunSettings(**SMALL, camera=CAM.to_dict())
    with Session.create(vol, settings=settings) as s:
        s.step()
        s.query(intent, generations=1)
        population = s.explorer.ask()
        assert any(c.tf.name == "fitted to the sketch" for c in population)
        assert any("joins the population" in line for line in s.understood)
        s.step()  # the fitted TF is rendered and judged like any candidate
