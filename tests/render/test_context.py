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


def test_shading_voxels_hold_the_gradient_and_the_value():
    """What a shaded sample reads, side by side: the gradient of ``gradient()`` and the value
    coded in 16 bits (an 8-bit volume's values exactly, any other within half a level)."""
    vol = _volume()
    lit = render_context(vol).shading_voxels()
    assert lit.dtype == np.int16 and lit.shape == vol.data.shape + (4,)
    assert np.shares_memory(lit, render_context(vol).gradient())
    g = np.empty(vol.data.shape + (3,), dtype=np.int16)
    kernels.central_gradient(vol.data, g)
    assert np.array_equal(lit[..., :3], g)
    decoded = lit[..., 3] * kernels.VALUE_CODE_SCALE + kernels.VALUE_CODE_OFFSET
    assert np.abs(decoded - vol.data).max() <= 0.5 / 65535 + 1e-7
    eight_bit = Volume.from_array(np.arange(256, dtype=np.uint8).reshape(4, 8, 8), name="levels")
    lit8 = render_context(eight_bit).shading_voxels()
    decoded = lit8[..., 3] * kernels.VALUE_CODE_SCALE + kernels.VALUE_CODE_OFFSET
    assert np.abs(decoded - eight_bit.data).max() < 1e-6
    assert len(np.unique(lit8[..., 3])) == 256


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
