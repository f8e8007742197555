"""The offline judge on real volumes: a painted box or fog never beats the clean picture, and
"show its structure clearly" is judged, not a tie."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from helpers.data import DATA
from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.types import Choice, Intent
from intuitf.intent.aspects import aspects_for
from intuitf.render import Camera, VolumeRenderer
from intuitf.tf import Gaussian
from intuitf.tf.defaults import background_cutoff, default_tf

CASES = {
    "bonsai_256x256x256_uint8.raw.gz": "A potted tree with brown pot, silver branch and golden leaves",
    "tooth_103x94x161_uint8.raw.gz": "a human tooth, show its structure clearly",
    "engine_256x256x128_uint8.raw.gz": "light blue translucent outer part and orange solid inner part",
}  # fmt: skip


@pytest.mark.parametrize("fname", list(CASES))
@pytest.mark.parametrize("fog", [(0.9, 0.8, 0.2), (0.3, 0.4, 0.9), (0.6, 0.75, 0.95)])
def test_fog_over_the_box_loses_on_real_volumes(fname, fog):
    if not (DATA / fname).exists():
        pytest.skip("no data")
    from intuitf.volume import load_volume

    vol = load_volume(DATA / fname, max_dim=96)
    counts, _ = vol.histogram()
    cut = background_cutoff(counts)
    mode = (np.argmax(counts[: max(1, int(cut * 255))]) + 0.5) / 256
    clean = default_tf(counts, vol.value_range)
    foggy = clean.with_gaussians([*clean.gaussians, Gaussian(float(mode), 0.03, 0.004, fog)])
    r = VolumeRenderer(vol, size=128)
    cam = Camera(azimuth=30.0, elevation=20.0)
    a, b = r.render(clean, cam), r.render(foggy, cam)
    j = MetricJudge()
    for aspects, intent in ((aspects_for("quality"), Intent()),
                            (aspects_for("text"), Intent(kind="text", text=CASES[fname]))):  # fmt: skip
        v = asyncio.run(j.compare(a, b, aspects, intent))
        assert v.overall is Choice.FIRST, (aspects[0].key, v.per_aspect)
