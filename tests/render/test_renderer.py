"""Behaviour of the ray caster and the sample cache, with real volumes and analytic cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from helpers.tfs import random_tf, tooth_tf
from intuitf.errors import RenderError
from intuitf.render import Camera, SampleCache, VolumeRenderer
from intuitf.tf import Gaussian, GaussianTF
from intuitf.volume import Volume


def _cube_volume(n=40, lo=10, hi=30, spacing=(1.0, 1.0, 1.0)) -> Volume:
    """A solid cube of value 1 occupying voxels [lo, hi) on every axis, 0 elsewhere."""
    a = np.zeros((n, n, n), dtype=np.uint8)
    a[lo:hi, lo:hi, lo:hi] = 255
    return Volume.from_array(a, spacing=spacing, name="cube")


OPAQUE_ONE = GaussianTF((Gaussian(mean=1.0, width=0.05, height=1.0, color=(1.0, 1.0, 1.0)),))


def _extent_px(mask: np.ndarray, axis: int) -> int:
    """Number of rows (axis 0) or columns (axis 1) holding any True pixel."""
    return int(np.count_nonzero(mask.any(axis=1 - axis)))


def test_camera_json_round_trip_and_validation():
    cam = Camera(azimuth=30, elevation=-20, roll=5, zoom=1.5, pan=(0.1, -0.2), fov=40)
    assert Camera.from_dict(cam.to_dict()) == cam
    with pytest.raises(RenderError):
        Camera(zoom=0)
    with pytest.raises(RenderError):
        Camera(projection="fisheye")
    with pytest.raises(RenderError):
        Camera.from_dict({"azimuth": 1, "tilt": 3})
    fwd, right, up = Camera().basis()
    np.testing.assert_allclose(fwd, [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(right, [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(up, [0, 0, 1], atol=1e-12)


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_a_view_projects_points_back_to_the_pixels_whose_rays_pass_through_them(projection):
    """ViewFrame.rays and ViewFrame.project are inverses: a point on a pixel's ray projects to
    that pixel's centre, at its distance along the view direction (perspective and
    orthographic, panned, on a picture that is not square)."""
    cam = Camera(azimuth=40.0, elevation=25.0, zoom=1.3, projection=projection, pan=(0.1, -0.05))
    frame = cam.frame((40.0, 30.0, 20.0), 48, 32)
    rows = np.array([0, 5, 17, 31])
    cols = np.array([0, 40, 23, 47])
    o, d = frame.rays(rows, cols)
    t = np.array([20.0, 35.0, 50.0, 80.0])
    row, col, depth = frame.project(o + t[:, None] * d)
    np.testing.assert_allclose(row, rows, atol=1e-9)
    np.testing.assert_allclose(col, cols, atol=1e-9)
    np.testing.assert_allclose(depth, ((o + t[:, None] * d) - frame.eye) @ frame.forward)


def test_renderer_rejects_bad_settings(neghip):
    with pytest.raises(RenderError):
        VolumeRenderer(neghip, size=0)
    with pytest.raises(RenderError):
        VolumeRenderer(neghip, background=(2, 0, 0))
    with pytest.raises(RenderError):
        VolumeRenderer(neghip, sample_distance=0)


def test_background_compositing_is_premultiplied_once():
    """A uniform slab seen along y: pixel = c·A + (1 - A)·bg with A = 1 - (1 - a)^length."""
    a = np.full((20, 40, 20), 255, dtype=np.uint8)
    a[0, 0, 0] = 0  # not constant
    vol = Volume.from_array(a)
    alpha, color, bg = 0.02, (0.2, 0.6, 1.0), (1.0, 1.0, 1.0)
    tf = GaussianTF((Gaussian(mean=1.0, width=0.05, height=alpha, color=color),))
    r = VolumeRenderer(vol, size=33, shading=False, background=bg, sample_distance=0.5)
    cam = Camera(projection="orthographic", zoom=2.0)
    img = r.render(tf, cam).astype(np.float64) / 255.0
    big_a = 1.0 - (1.0 - alpha) ** 39  # the box through voxel centres is 39 voxels deep
    expected = np.array(color) * big_a + (1.0 - big_a) * np.array(bg)
    np.testing.assert_allclose(img[16, 16], expected, atol=1.5 / 255)
    # Alpha multiplied twice would give c·A² + (1 - A)·bg: far from what we see.
    wrong = np.array(color) * big_a**2 + (1.0 - big_a) * np.array(bg)
    assert np.abs(img[16, 16] - wrong).max() > 0.1
    # Where no ray meets the volume the background shows exactly.
    np.testing.assert_array_equal(r.render(tf, cam)[0, 0], [255, 255, 255])


def test_sampling_rate_does_not_change_the_picture(foot):
    rng = np.random.default_rng(3)
    cam = Camera(azimuth=40, elevation=25)
    tfs = [random_tf(rng) for _ in range(3)]
    for shading in (False, True):
        imgs = {
            sd: [
                VolumeRenderer(foot, size=96, shading=shading, sample_distance=sd).render(t, cam)
                for t in tfs
            ]
            for sd in (0.25, 0.5, 1.0)
        }
        for sd, bound in ((0.5, 1.0), (1.0, 2.0)):
            for a, b in zip(imgs[0.25], imgs[sd], strict=True):
                d = a.astype(int) - b.astype(int)
                # No drift in brightness; what differs is the finer sampling of narrow
                # Gaussians, which shrinks with the step.
                assert abs(d.mean()) < 0.5, (shading, sd, d.mean())
                assert np.abs(d).mean() < bound, (shading, sd, np.abs(d).mean())
    # Without opacity correction the step would matter a lot: check the test can fail.
    r = VolumeRenderer(foot, size=96, shading=False, sample_distance=1.0)
    tf = tfs[0]
    lut_uncorrected = tf.lut(foot.lut_size, 1.0)
    r.lut = lambda _tf: lut_uncorrected  # type: ignore[method-assign]
    r.sample_distance = 0.25
    wrong = r.render(tf, cam)
    assert (wrong.astype(int) - imgs[0.25][0].astype(int)).mean() > 2.0


def test_cache_matches_direct_renderer_within_quantisation(tooth, foot):
    """The bounds stated in SampleCache's docstring."""
    rng = np.random.default_rng(7)
    for vol in (tooth, foot):
        for shading in (False, True):
            r = VolumeRenderer(vol, size=80, shading=shading)
            for cam in (Camera(azimuth=30, elevation=20), Camera(projection="orthographic")):
                cache = r.sample_cache(cam)
                assert isinstance(cache, SampleCache)
                for _ in range(4):
                    tf = random_tf(rng)
                    cached = cache.render_rgba(tf)
                    # With the cache's own rounding the direct renderer gives the same picture.
                    same = np.abs(cached - r.render_rgba(tf, cam, nearest=True))
                    assert same.max() <= (1.0 / 255 if shading else 1e-5), same.max() * 255
                    d = np.abs(cached - r.render_rgba(tf, cam)) * 255
                    assert d.mean() < 0.5 and np.percentile(d, 99.9) < 8 and d.max() < 20
                    assert d.max() > 0  # the two paths are really different code


def test_empty_space_skipping_changes_no_pixel(foot):
    """The renderer's two skipping grids (8³ blocks jumped over, 2³ blocks passed over) give
    exactly the picture of marching every sample, and do skip: most of the foot's blocks are
    invisible to a TF of its bone alone. Pre-integrated too, where a skipped stretch's first
    and last segments (into and out of the bone) must still be classified, and with a
    Gaussian so narrow that only those segments show it."""
    from intuitf.render import kernels
    from intuitf.render.context import BLOCK_SIZE, FINE_BLOCK_SIZE
    from intuitf.render.renderer import EARLY_STOP

    bone = GaussianTF((Gaussian(mean=0.6, width=0.05, height=0.4, color=(1.0, 0.9, 0.8)),))
    shell = GaussianTF((Gaussian(mean=0.3, width=0.002, height=0.6, color=(0.2, 0.5, 1.0)),))
    for preintegrated in (False, True):
        for tf in (bone, shell) if preintegrated else (bone,):
            for shading in (False, True):
                r = VolumeRenderer(foot, size=96, shading=shading, preintegrated=preintegrated)
                for cam in (
                    Camera(azimuth=35, elevation=25),
                    Camera(azimuth=90, elevation=-60, roll=20),
                ):
                    cls = r.classification(tf)
                    coarse = r._visible_blocks(cls.occupied, BLOCK_SIZE)
                    fine = r._visible_blocks(cls.occupied, FINE_BLOCK_SIZE)
                    assert coarse.mean() < 0.6 and fine.mean() < coarse.mean()
                    every = np.empty((96 * 96, 4), dtype=np.float32)
                    kernels.march(foot.data, r._shading_voxels(), shading, np.ones_like(coarse),
                                  BLOCK_SIZE, np.ones_like(fine), 1, cls.lut, cls.table,
                                  preintegrated, False, r.frame(cam).packed(), r._spacing,
                                  r.sample_distance, r.shade_params, EARLY_STOP,
                                  every)  # fmt: skip
                    skipped = r.render_rgba(tf, cam)
                    assert skipped[..., 3].max() > 0.5  # the bone (or the shell) shows
                    np.testing.assert_array_equal(skipped.reshape(-1, 4), every)


def test_cache_stores_uint16_samples_for_wide_luts():
    a = (np.random.default_rng(0).random((24, 24, 24)) * 3000).astype(np.uint16)
    vol = Volume.from_array(a, value_range=(0, 2999))
    vol.original_dtype = "uint16"
    assert vol.lut_size == 3000
    r = VolumeRenderer(vol, size=32, shading=False)
    cache = r.sample_cache(Camera())
    assert cache.samples.dtype == np.uint16
    tf = GaussianTF((Gaussian(0.5, 0.1, 0.3, (1, 0.5, 0)),))
    d = np.abs(cache.render_rgba(tf) - r.render_rgba(tf, Camera()))
    assert d.max() < 2 / 255


def test_orthographic_and_perspective_geometry():
    """The cube's silhouette has the size projection geometry predicts, to a pixel."""
    vol = _cube_volume()  # box 39³ through voxel centres, cube faces at 10 and 29
    w = 101
    r = VolumeRenderer(vol, size=w, shading=False)
    radius = 0.5 * math.sqrt(3) * 39
    side = 19.0  # from voxel centre 10 to voxel centre 29 (value 0.5 crossing adds ~1)
    ortho = r.render_rgba(OPAQUE_ONE, Camera(projection="orthographic"))[..., 3] > 0.5
    px = w / (2 * radius)  # pixels per world unit at zoom 1
    assert abs(_extent_px(ortho, 1) - (side + 1) * px) <= 1.5
    assert abs(_extent_px(ortho, 0) - (side + 1) * px) <= 1.5
    side_eff = _extent_px(ortho, 1) / px  # where the opaque TF makes the surface
    widths = {}
    for fov in (30.0, 90.0):
        persp = r.render_rgba(OPAQUE_ONE, Camera(fov=fov))[..., 3] > 0.5
        d = radius / math.sin(math.radians(fov / 2))
        near = d - side_eff / 2  # the silhouette is the front face, nearer than the centre
        expected = side_eff / near / math.tan(math.radians(fov / 2)) * w / 2
        widths[fov] = _extent_px(persp, 1)
        assert abs(widths[fov] - expected) <= 1.5, (fov, widths[fov], expected)
    # A wide angle brings the camera close: the cube then fills less of the fitted view.
    assert widths[90.0] < widths[30.0] - 2
    # Zoom 2 doubles the silhouette.
    zoomed = r.render_rgba(OPAQUE_ONE, Camera(projection="orthographic", zoom=2))[..., 3] > 0.5
    assert abs(_extent_px(zoomed, 1) - 2 * _extent_px(ortho, 1)) <= 2


def test_anisotropic_spacing_keeps_proportions():
    """Voxels twice as long in z make a cube of voxels twice as tall as wide (front view)."""
    vol = _cube_volume(spacing=(1.0, 1.0, 2.0))
    r = VolumeRenderer(vol, size=(96, 128), shading=False)
    mask = r.render_rgba(OPAQUE_ONE, Camera(projection="orthographic"))[..., 3] > 0.5
    ratio = _extent_px(mask, 0) / _extent_px(mask, 1)
    assert abs(ratio - 2.0) < 0.12, ratio
    # Seen from above (elevation 90) it is square again.
    top = r.render_rgba(OPAQUE_ONE, Camera(projection="orthographic", elevation=90))[..., 3] > 0.5
    assert abs(_extent_px(top, 0) / _extent_px(top, 1) - 1.0) < 0.08


def test_view_direction_convention():
    """Front view: +x to the right, +z up; azimuth 90 looks from +x, so +y is to the right."""
    a = np.zeros((32, 32, 32), dtype=np.uint8)
    a[4:10, 14:18, 24:30] = 255  # a blob at high x, middle y, low z
    vol = Volume.from_array(a)
    r = VolumeRenderer(vol, size=64, shading=False)
    front = r.render_rgba(OPAQUE_ONE, Camera(projection="orthographic"))[..., 3]
    ys, xs = np.nonzero(front > 0.5)
    assert xs.mean() > 32 and ys.mean() > 32  # right (high x) and low in the picture (low z)
    side = r.render_rgba(OPAQUE_ONE, Camera(projection="orthographic", azimuth=90))[..., 3]
    ys, xs = np.nonzero(side > 0.5)
    assert abs(xs.mean() - 31.5) < 3 and ys.mean() > 32  # y is centred; still low
    # Positive roll turns the picture clockwise: the lower-right blob moves to the lower left.
    rolled = r.render_rgba(OPAQUE_ONE, Camera(projection="orthographic", roll=90))[..., 3]
    ys, xs = np.nonzero(rolled > 0.5)
    assert xs.mean() < 32 and ys.mean() > 32
    # Pan moves the content right by the given fraction of the width.
    panned = r.render_rgba(OPAQUE_ONE, Camera(projection="orthographic", pan=(0.25, 0)))[..., 3]
    assert abs(np.nonzero(panned > 0.5)[1].mean() - np.nonzero(front > 0.5)[1].mean() - 16) < 1


def test_attribution_sums_to_alpha(tooth):
    r = VolumeRenderer(tooth, size=64, shading=True)
    cache = r.sample_cache(Camera(azimuth=20, elevation=10))
    rng = np.random.default_rng(11)
    for tf in (tooth_tf(), random_tf(rng, 4)):
        attr = cache.attribution(tf)
        assert attr.shape == (len(tf), 64, 64) and attr.dtype == np.float32
        assert attr.min() >= 0
        alpha = cache.render_rgba(tf)[..., 3]
        np.testing.assert_allclose(attr.sum(axis=0), alpha, atol=2e-4)
        assert alpha.max() > 0.5  # the test is not vacuous


def test_pick_finds_the_gaussian_placed_at_a_structure(tooth):
    """Enamel (values near 0.92) caps the crown at the top; dentin fills the root below."""
    tf = tooth_tf()
    r = VolumeRenderer(tooth, size=64, shading=False)
    cache = r.sample_cache(Camera(projection="orthographic", zoom=1.3))
    enamel_alone = cache.render_rgba(tf.only(1))[..., 3]
    dentin_alone = cache.render_rgba(tf.only(0))[..., 3]
    rows = np.nonzero(enamel_alone.max(axis=1) > 0.5)[0]
    assert rows.mean() < 32  # the crown is in the upper half: +z is up
    y, x = np.unravel_index(np.argmax(enamel_alone), enamel_alone.shape)
    picked = cache.pick(tf, int(x), int(y))
    assert picked[0][0] == 1 and picked[0][1] > 0.5
    # Low in the root only dentin shows.
    root = np.nonzero((dentin_alone > 0.3) & (enamel_alone < 0.01))
    k = np.argmax(root[0])
    picked = cache.pick(tf, int(root[1][k]), int(root[0][k]), radius=1)
    assert [i for i, _ in picked] == [0]
    assert cache.pick(tf, 0, 0) == []  # background
    with pytest.raises(RenderError):
        cache.pick(tf, 64, 0)


def test_render_feature_shows_one_gaussian_over_a_ghost(tooth):
    tf = tooth_tf()
    r = VolumeRenderer(tooth, size=64, shading=False, background=(0, 0, 0))
    cache = r.sample_cache(Camera(projection="orthographic"))
    img = cache.render_feature(tf, 1, ghost=0.1).astype(int)
    enamel = cache.render_rgba(tf.only(1))[..., 3]
    full = cache.render(tf).astype(int)
    # Away from the enamel only a faint grey ghost of the full rendering remains.
    away = (enamel < 1e-3) & (full.sum(axis=2) > 150)
    assert away.any()
    assert img[away].max() <= 0.1 * 255 + 1
    assert np.abs(img[away][:, 0] - img[away][:, 2]).max() <= 1  # grey
    # On the enamel its own (near-white) colour shows.
    on = enamel > 0.9
    assert img[on].mean() > 200
    with pytest.raises(RenderError):
        cache.render_feature(tf, 5)


def test_preintegration_renders_a_thin_shell_as_fine_sampling_does(tooth):
    """A Gaussian thinner than the values' step between samples: classified sample by sample
    it shows as rings (each ray hits it or not), pre-integrated as the even shell that
    sampling ten times finer shows. The segment table's diagonal is the LUT, so a wide TF's
    picture barely changes."""
    from skimage.color import deltaE_ciede2000, rgb2lab

    thin = GaussianTF((
        Gaussian(mean=0.45, width=0.004, height=0.5, color=(0.2, 0.5, 1.0)),
        Gaussian(mean=0.7, width=0.05, height=0.5, color=(0.95, 0.95, 0.85)),
    ))  # fmt: skip
    cam = Camera(azimuth=75, elevation=10, zoom=1.3)

    def picture(tf, **kw):
        return VolumeRenderer(tooth, size=96, **kw).render(tf, cam)

    reference = rgb2lab(picture(thin, sample_distance=0.05, preintegrated=False) / 255.0)
    lit = reference[..., 0] > 3

    def error(img):
        return float(deltaE_ciede2000(rgb2lab(img / 255.0), reference)[lit].mean())

    post = error(picture(thin, preintegrated=False))
    pre = error(picture(thin))
    assert pre < 0.4 * post, (pre, post)
    assert error(picture(thin, sample_distance=1.0)) < post  # twice the step, still better
    wide = tooth_tf()
    d = np.abs(picture(wide).astype(int) - picture(wide, preintegrated=False).astype(int))
    assert d.mean() < 1.0, d.mean()
