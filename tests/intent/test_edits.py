"""Edits do what they say, and what the words hide (the background) stays hidden."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from intuitf.evaluator.types import Intent
from intuitf.explorer import make_explorer
from intuitf.explorer.bounds import Bounds, rgb_to_hsl
from intuitf.explorer.hints import HIDDEN_EPS, Hint, as_hints, quiet_hidden
from intuitf.intent.hints import edit_direction, explorer_hints
from intuitf.tf import Gaussian, GaussianTF
from intuitf.volume import Volume

BASE = GaussianTF(
    (
        Gaussian(0.2, 0.03, 0.05, (0.9, 0.6, 0.3)),
        Gaussian(0.5, 0.04, 0.3, (0.2, 0.4, 0.9)),
        Gaussian(0.8, 0.02, 0.6, (0.95, 0.95, 0.9)),
    )
)


def first_refined_generation(text: str, selected=(1,), seed: int = 0):
    hints = explorer_hints(Intent(kind="edit", text=text, selected=selected))
    ex = make_explorer("ga", population=12, n_gaussians=3, generations=2, seed=seed,
                       initial=[BASE], hints=hints)  # fmt: skip
    ex.set_stage("refine", generations=2, selected=selected, base=BASE)
    return [c.tf for c in ex.ask() if c.origin != "initial"]


@pytest.mark.parametrize(
    ("text", "direction"),
    [("transparent", "fainter"), ("make it faint", "fainter"), ("hide it", "hidden"),
     ("more opaque", "stronger"), ("brighter", "brighter"), ("make it gold", None)],
)  # fmt: skip
def test_edit_words_have_a_direction(text, direction):
    assert edit_direction(text) == direction


def test_transparent_lowers_the_selected_opacity_and_keeps_everything_else():
    tfs = first_refined_generation("transparent")
    assert len(tfs) >= 8
    for tf in tfs:
        g, b = tf.gaussians[1], BASE.gaussians[1]
        assert g.height <= 0.35 * b.height + 1e-9  # clearly fainter, in every candidate
        assert (g.mean, g.width) == (b.mean, b.width)
        assert np.allclose(g.color, b.color)  # no colour word: the colour stays
        for k in (0, 2):  # the rest is frozen as it was
            assert replace(tf.gaussians[k], frozen=False) == BASE.gaussians[k]


def test_hide_more_opaque_brighter_and_colour_words():
    assert all(tf.gaussians[1].height == 0.0 for tf in first_refined_generation("hide it"))
    for tf in first_refined_generation("make it more opaque"):
        assert tf.gaussians[1].height >= 1.5 * BASE.gaussians[1].height - 1e-9
    lum0 = rgb_to_hsl(BASE.gaussians[1].color)[2]
    for tf in first_refined_generation("brighter"):
        assert rgb_to_hsl(tf.gaussians[1].color)[2] > lum0 + 0.05
    gold = np.array([212, 175, 55]) / 255.0
    for tf in first_refined_generation("make it gold"):
        assert np.abs(np.array(tf.gaussians[1].color) - gold).max() < 0.2


def test_a_hidden_material_gets_no_opacity_from_any_candidate():
    bg = Hint("background", center=0.02, spread=0.02, hidden=True)
    b = Bounds()
    on_it = GaussianTF((Gaussian(0.03, 0.02, 0.5, (1, 1, 0)),))
    assert quiet_hidden(on_it, [bg], b).gaussians[0].height == 0.0
    tail = GaussianTF((Gaussian(0.2, 0.07, 0.8, (1, 1, 0)),))
    g = quiet_hidden(tail, [bg], b).gaussians[0]
    assert g.width < 0.07 and g.height == 0.8
    s = np.linspace(0.0, 0.04, 50)
    assert float(GaussianTF((g,)).opacity(s).max()) <= HIDDEN_EPS * 1.01


def test_a_faint_gaussian_on_the_air_leaves_no_fog_over_the_box():
    # A head CT's air under a Gaussian of height 1.5e-3: little per voxel, but summed over a
    # ray through the whole box it drew the box as a red fog (13 % alpha across 96 voxels).
    rng = np.random.default_rng(1)
    data = rng.normal(0.02, 0.005, (96, 96, 96))
    data[40:56, 40:56, 40:56] = 0.6
    vol = Volume.from_array(data.clip(0, 1).astype(np.float32), value_range=(0.0, 1.0))
    hints = as_hints(explorer_hints(Intent(kind="text", text="ivory block"), vol))
    faint = GaussianTF((Gaussian(0.03, 0.03, 1.5e-3, (0.9, 0.1, 0.1)),
                        Gaussian(0.6, 0.03, 0.8, (1.0, 1.0, 0.9))))  # fmt: skip
    quiet = quiet_hidden(faint, hints, Bounds())
    from intuitf.render import Camera, VolumeRenderer

    r = VolumeRenderer(vol, size=64, shading=False, device="cpu")
    alpha = r.render_rgba(quiet, Camera(azimuth=30.0, elevation=20.0))[..., 3]
    block = r.render_rgba(GaussianTF((faint.gaussians[1],)), Camera(azimuth=30.0, elevation=20.0))
    air = block[..., 3] < 0.01  # rays through air alone
    assert air.mean() > 0.3
    assert float(alpha[air].max()) < 0.02


def test_a_tail_reaching_the_air_leaves_no_veil_over_the_body():
    # The chest CT's air is 0.0 (masked), its background hint 0.002 +- 0.007. A faint red
    # Gaussian at 0.13 (its fat) kept to 2e-3 at the hint's edge, yet gave 0.0 5e-4 per voxel:
    # a red veil over the whole box (5 % alpha across 96 voxels of air, 0.5 % now).
    rng = np.random.default_rng(1)
    data = np.zeros((96, 96, 96))
    data[24:72, 24:72, 24:72] = rng.normal(0.13, 0.01, (48, 48, 48))
    data[40:56, 40:56, 40:56] = 0.6
    vol = Volume.from_array(data.clip(0, 1).astype(np.float32), value_range=(0.0, 1.0))
    hints = [Hint("background", center=0.002, spread=0.007, hidden=True)]
    skin = Gaussian(0.13, 0.041, 0.072, (0.97, 0.16, 0.16))
    quiet = quiet_hidden(GaussianTF((skin,)), hints, Bounds()).gaussians[0]
    assert quiet.height == skin.height and quiet.width < skin.width  # narrowed, still there
    from scipy import ndimage

    from intuitf.render import Camera, VolumeRenderer

    cam = Camera(azimuth=30.0, elevation=20.0)
    body = Volume.from_array((data > 0).astype(np.float32), value_range=(0.0, 1.0))
    solid = GaussianTF((Gaussian(1.0, 0.05, 1.0, (1.0, 1.0, 1.0)),))
    air = VolumeRenderer(body, size=64, shading=False, device="cpu").render_rgba(solid, cam)
    # Rays through air alone, two pixels off the body's outline (its partial values are fat).
    air = ndimage.binary_erosion(air[..., 3] < 0.01, iterations=2, border_value=1)
    r = VolumeRenderer(vol, size=64, shading=False, device="cpu")
    assert air.mean() > 0.3
    assert float(r.render_rgba(GaussianTF((quiet,)), cam)[..., 3][air].max()) < 0.02


@pytest.mark.parametrize("kind", ["none", "sketch", "text"])
def test_every_first_population_keeps_the_background_clear(kind):
    rng = np.random.default_rng(0)
    data = rng.normal(0.04, 0.01, (32, 32, 32))
    data[8:24, 8:24, 8:24] = rng.normal(0.5, 0.03, (16, 16, 16))
    data[12:20, 12:20, 12:20] = rng.normal(0.85, 0.02, (8, 8, 8))
    vol = Volume.from_array(data.clip(0, 1).astype(np.float32), value_range=(0.0, 1.0))
    intent = Intent(kind=kind, text="red block" if kind == "text" else None)
    hints = as_hints(explorer_hints(intent, vol))
    bg = [h for h in hints if h.name == "background"]
    assert len(bg) == 1 and bg[0].hidden
    ex = make_explorer("ga", population=24, n_gaussians=5, generations=3, seed=3,
                       histogram=vol.histogram()[0], hints=hints)  # fmt: skip
    lo, hi = bg[0].center - bg[0].spread, bg[0].center + 2.5 * bg[0].spread
    s = np.linspace(max(0.0, lo), hi, 40)
    for c in ex.ask():
        assert float(c.tf.opacity(s).max()) <= 5 * HIDDEN_EPS, c.id
