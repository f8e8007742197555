"""The offline judge on labelled pairs of real renderings: clean beats haze, noise, blank, shell.

The pairs (``tests/data/judge_pairs``, built by ``benchmarks/judge_pairs.py build``) are
renderings of six real volumes (foot, head, tooth, engine, bonsai, carp); in each, one side is
a clean transfer function and the other the same one spoilt: a grey veil over the volume's box
(haze), speckle from the noise above the background, next to nothing shown (blank), the
outermost material as one opaque shell, or washed-out colours. The paper's entropy baseline
agreed with these labels on 0.62 of them (haze 0.50, noise 0.08, shell 0.50).
"""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import numpy as np
import pytest

from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.metric_quality import quality
from intuitf.evaluator.types import Choice, Intent
from intuitf.imageio import load_image
from intuitf.intent.aspects import aspects_for

PAIRS = Path(__file__).resolve().parents[1] / "data" / "judge_pairs"


def _pairs():
    labels = json.loads((PAIRS / "labels.json").read_text())
    return [
        (p, load_image(PAIRS / p["first"]), load_image(PAIRS / p["second"]))
        for p in labels["pairs"]
    ]


def _hit(verdict, better: str) -> float:
    score = verdict.overall.score  # 1 first, 0.5 tie, 0 second
    return score if better == "first" else 1.0 - score


def test_labelled_pairs_agreement():
    judge = MetricJudge()
    quality_aspects = aspects_for("quality")
    by_kind: dict[str, list[float]] = {}
    for p, a, b in _pairs():
        v = asyncio.run(judge.compare(a, b, quality_aspects, Intent()))
        by_kind.setdefault(p["kind"], []).append(_hit(v, p["better"]))
    agreement = {k: float(np.mean(v)) for k, v in by_kind.items()}
    overall = float(np.mean([h for v in by_kind.values() for h in v]))
    assert set(agreement) == {"haze", "noise", "blank", "shell", "washed"}
    assert len(by_kind["haze"]) == 6  # six volumes
    # Measured 0.98 (shell 0.92); the entropy baseline reached 0.62.
    assert overall >= 0.9, agreement
    for kind in ("haze", "noise", "blank", "washed"):
        assert agreement[kind] == 1.0, agreement
    assert agreement["shell"] >= 0.75, agreement


def test_order_does_not_matter():
    judge = MetricJudge()
    asp = aspects_for("quality")
    for _p, a, b in _pairs()[:10]:
        v1 = asyncio.run(judge.compare(a, b, asp, Intent()))
        v2 = asyncio.run(judge.compare(b, a, asp, Intent()))
        assert v1.overall == v2.overall.swapped()


def test_haze_is_a_veil_and_noise_is_grain():
    clean = quality(load_image(PAIRS / "engine_clean.png"))
    haze = quality(load_image(PAIRS / "engine_haze.png"))
    noise = quality(load_image(PAIRS / "engine_noise.png"))
    blank = quality(load_image(PAIRS / "engine_blank.png"))
    assert haze.veil > 0.4 > 0.1 > clean.veil
    assert noise.grain > clean.grain + 0.3
    assert clean.clarity > 4 * max(haze.clarity, noise.clarity)
    assert blank.richness == blank.discrimination == 0.0


@pytest.mark.parametrize("volume", ["foot", "head", "tooth"])
def test_text_alignment_counts_haze_against_a_rendering(volume):
    """With the same colours on show, the hazy rendering loses on the text aspect too."""
    text = {
        "foot": "faint red skin, opaque ivory bone",
        "head": "faint red skin, opaque ivory bone",
        "tooth": "ivory dentin, opaque blue crown",
    }[volume]
    clean = load_image(PAIRS / f"{volume}_clean.png")
    haze = load_image(PAIRS / f"{volume}_haze.png")
    v = asyncio.run(
        MetricJudge().compare(clean, haze, aspects_for("text"), Intent(kind="text", text=text))
    )
    assert v.overall is Choice.FIRST, v.rationale


def test_a_painted_box_is_seen():
    """Painting the background's values fills the volume's box: its straight outline shows."""
    for p, a, b in _pairs():
        if p["kind"] != "haze":
            continue
        clean, haze = (a, b) if p["better"] == "first" else (b, a)
        assert quality(haze).box, p
        assert not quality(clean).box, p


@pytest.fixture(scope="module")
def chest_render(data_dir):
    """The chest CT (full size) as the judge sees it: a TF's 128-pixel shaded picture."""
    from intuitf.render import Camera, VolumeRenderer
    from intuitf.volume import load_volume

    vol = load_volume(data_dir / "chestlidc2_256x256x133_uint8.raw.gz")
    renderer = VolumeRenderer(vol, size=128, shading=True, background=(0.0, 0.0, 0.0))
    camera = Camera(azimuth=0.0, elevation=10.0)
    return lambda tf: renderer.render(tf, camera)


@pytest.fixture(scope="module")
def chest_pictures(chest_render):
    """The chest with opaque ivory ribs under a faint red body, and painted red all over
    without its ribs (what a search reached when the judge could not see the ribs)."""
    from intuitf.tf import Gaussian, GaussianTF

    ivory, red = (0.98, 0.96, 0.88), (0.86, 0.12, 0.12)
    ribs = GaussianTF((Gaussian(0.525, 0.05, 0.8, ivory), Gaussian(0.098, 0.03, 0.03, red)))
    painted = GaussianTF((Gaussian(0.064, 0.015, 0.1, red),))
    return chest_render(ribs), chest_render(painted)


def test_thin_structures_are_not_grain(chest_pictures):
    """Ribs at 128 px are lines of fine detail, not speckle: counted as grain they read as
    noisier than the noise pairs' speckle (1.32), and the judge preferred a blurred chest."""
    ribs, _ = chest_pictures
    q = quality(ribs)
    assert q.grain < 0.7, q
    assert q.clarity > 0.7, q
    noise = quality(load_image(PAIRS / "foot_noise.png"))
    assert noise.grain > q.grain + 0.3


def test_shaded_ivory_ribs_meet_opaque_ivory_bone(chest_pictures):
    """Shaded thin ribs never show ivory's full lightness (L* 54-81): the words still see them."""
    ribs, painted = chest_pictures
    intent = Intent(kind="text", text="opaque ivory bone and faint red skin")
    v = asyncio.run(MetricJudge().compare(ribs, painted, aspects_for("text"), intent))
    assert v.overall is Choice.FIRST, v.rationale


def test_a_faint_red_skin_is_not_traded_for_more_ivory(chest_render):
    """'Faint red skin' tints the whole body it wraps. A search once turned the chest's soft
    tissue (under a faint red edge) ivory: the ivory clause rose, while the red one, full at
    30 % of the picture, could not tell 47 % red from 30 %; the body read ΔE 33 from red."""
    from intuitf.tf import Gaussian, GaussianTF

    # The first generation's best and the last's, of one seed of the benchmark's chest case.
    red_body = GaussianTF((Gaussian(0.040, 0.009, 0.052, (0.89, 0.19, 0.13)),
                           Gaussian(0.078, 0.017, 0.017, (0.86, 0.23, 0.24)),
                           Gaussian(0.526, 0.080, 0.814, (0.99, 0.97, 0.91))))  # fmt: skip
    ivory_body = GaussianTF((Gaussian(0.039, 0.005, 0.054, (0.88, 0.14, 0.14)),
                             Gaussian(0.078, 0.017, 0.017, (0.97, 0.95, 0.88)),
                             Gaussian(0.526, 0.080, 0.814, (1.00, 0.98, 0.90))))  # fmt: skip
    intent = Intent(kind="text", text="opaque ivory bone and faint red skin")
    v = asyncio.run(
        MetricJudge().compare(
            chest_render(red_body), chest_render(ivory_body), aspects_for("text"), intent
        )
    )
    assert v.overall is Choice.FIRST, v.rationale
