"""The render context: one gradient and one set of block ranges per volume, whatever the number
of renderers, views and front ends; the device a run names is the one its views use."""

from __future__ import annotations

import gc
import weakref

import numpy as np

from helpers.tfs import random_tf
from intuitf.render import Camera, VolumeRenderer, kernels
from intuitf.render.context import render_context
from intuitf.session.views import ViewRenderer
from intuitf.volume import Volume
from intuitf.volume.phantom import phantom_array


def _volume(n: int = 24, seed: int = 0) -> Volume:
    return Volume.from_array(phantom_array(n, seed), name=f"phantom{n}")


def test_renderers_of_a_volume_share_one_gradient_and_block_ranges():
    vol = _volume()
    a = VolumeRenderer(vol, size=32, device="cpu")
    b = VolumeRenderer(vol, size=48, shading=False, device="cpu")
    views = ViewRenderer(vol, device="cpu")
    c = views.renderer(40, True)
    assert a.context is b.context is c.context is render_context(vol)
    assert a.gradient() is c.gradient()
    assert a._block_ranges()[0] is b._block_ranges()[0]
    # Its gradient is the kernel's, computed once.
    g = np.empty(vol.data.shape + (3,), dtype=np.int16)
    kernels.central_gradient(vol.data, g)
    assert np.array_equal(a.gradient(), g)
    assert render_context(vol).nbytes() >= g.nbytes
    # Another volume has its own context.
    assert VolumeRenderer(_volume(seed=1), size=32).context is not a.context


def test_the_context_goes_with_its_volume():
    vol = _volume()
    VolumeRenderer(vol, size=16, device="cpu").gradient()
    ref = weakref.ref(render_context(vol))
    del vol
    gc.collect()
    assert ref() is None


def test_the_first_named_device_is_the_volumes():
    vol = _volume()
    assert VolumeRenderer(vol, size=16).device in ("cpu", "cuda")  # "auto" before any is named
    ctx = render_context(vol, "cpu")
    assert ctx.device == "cpu"
    assert VolumeRenderer(vol, size=16).device == "cpu"
    assert ViewRenderer(vol).renderer(16, True).device == "cpu"
    assert render_context(vol, "auto").device == "cpu"  # named once, kept


def test_small_pictures_composite_to_the_kernels_bytes():
    vol = _volume(32)
    r = VolumeRenderer(vol, size=40, background=(0.2, 0.5, 0.9), device="cpu")
    rgba = r.render_rgba(random_tf(np.random.default_rng(3)), Camera(azimuth=30, elevation=20))
    assert rgba[..., 3].max() > 0.1
    h, w = rgba.shape[:2]
    kernel = np.empty((h * w, 3), dtype=np.uint8)
    kernels.to_rgb8(np.ascontiguousarray(rgba.reshape(h * w, 4)), r.background, kernel)
    assert np.array_equal(r.to_rgb8_single(rgba), kernel.reshape(h, w, 3))
    assert np.array_equal(r.to_rgb8(rgba), kernel.reshape(h, w, 3))
    tf = random_tf(np.random.default_rng(3))
    assert np.array_equal(r.render(tf, Camera(azimuth=30, elevation=20)), kernel.reshape(h, w, 3))
