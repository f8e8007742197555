"""GaussianTF: validation, evaluation, lookup table, editing helpers and JSON form."""

from __future__ import annotations

import json

import numpy as np
import pytest

from intuitf.errors import TransferFunctionError
from intuitf.tf import Gaussian, GaussianTF, load_tf, save_tf

RED = (1.0, 0.0, 0.0)
BLUE = (0.0, 0.0, 1.0)


def two_peaks(**kw) -> GaussianTF:
    return GaussianTF(
        (
            Gaussian(mean=0.3, width=0.05, height=0.4, color=RED),
            Gaussian(mean=0.7, width=0.02, height=0.8, color=BLUE, frozen=True),
        ),
        **kw,
    )


# -- validation -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "field, value",
    [
        ("mean", -0.01),
        ("mean", 1.01),
        ("width", 0.001),
        ("width", 0.6),
        ("height", -0.1),
        ("height", 1.5),
        ("mean", float("nan")),
        ("height", float("inf")),
        ("mean", "abc"),
        ("width", None),
    ],
)
def test_gaussian_rejects_out_of_range_parameters(field, value):
    params = dict(mean=0.5, width=0.05, height=0.5, color=RED)
    params[field] = value
    with pytest.raises(TransferFunctionError):
        Gaussian(**params)


@pytest.mark.parametrize(
    "color", [(1.0, 0.0), (1.0, 0.0, 0.0, 1.0), (1.2, 0.0, 0.0), (0, -1, 0), ("x", 0, 0)]
)
def test_gaussian_rejects_bad_colors(color):
    with pytest.raises(TransferFunctionError):
        Gaussian(mean=0.5, width=0.05, height=0.5, color=color)


def test_gaussian_accepts_range_bounds_and_normalises_types():
    g = Gaussian(mean=1, width=0.5, height=0, color=[0, 1, 0], frozen=1)
    assert (g.mean, g.width, g.height) == (1.0, 0.5, 0.0)
    assert g.color == (0.0, 1.0, 0.0) and isinstance(g.color, tuple)
    assert g.frozen is True


def test_tf_needs_one_to_sixteen_gaussians():
    g = Gaussian(0.5, 0.05, 0.5, RED)
    with pytest.raises(TransferFunctionError):
        GaussianTF(())
    with pytest.raises(TransferFunctionError):
        GaussianTF((g,) * 17)
    assert len(GaussianTF((g,) * 16)) == 16


@pytest.mark.parametrize(
    "vr", [(1.0, 1.0), (2.0, 1.0), (0.0, float("nan")), (0.0, 1.0, 2.0), ("a", "b"), 5]
)
def test_tf_rejects_bad_value_range(vr):
    with pytest.raises(TransferFunctionError):
        two_peaks(value_range=vr)


# -- evaluation -----------------------------------------------------------------------------
def test_opacity_is_sum_of_gaussians_and_clamped():
    tf = two_peaks()
    assert tf.opacity(np.array([0.3]))[0] == pytest.approx(
        0.4 + 0.8 * np.exp(-0.5 * (0.4 / 0.02) ** 2)
    )
    # One standard deviation from the first mean.
    assert tf.opacity(np.array([0.35]))[0] == pytest.approx(0.4 * np.exp(-0.5), rel=1e-9)
    heavy = GaussianTF((Gaussian(0.5, 0.1, 0.9, RED), Gaussian(0.52, 0.1, 0.9, BLUE)))
    a = heavy.opacity(np.linspace(0, 1, 101))
    assert a.max() == 1.0  # 1.8 clamped
    assert a.min() >= 0.0


def test_color_is_weighted_by_contribution_not_a_ramp_between_centres():
    tf = GaussianTF((Gaussian(0.2, 0.05, 0.5, RED), Gaussian(0.8, 0.05, 0.1, BLUE)))
    c = tf.color(np.array([0.2, 0.8, 0.5, 0.45]))
    np.testing.assert_allclose(c[0], RED, atol=1e-9)
    np.testing.assert_allclose(c[1], BLUE, atol=1e-9)
    # Half way between equal-width Gaussians, weights are the heights: 0.5 : 0.1.
    np.testing.assert_allclose(c[2], [5 / 6, 0.0, 1 / 6], atol=1e-9)
    # A straight ramp would give 0.42 red at 0.45; the contribution blend is all red there.
    assert c[3][0] > 0.99


def test_color_far_from_every_gaussian_is_the_nearest_one_and_finite():
    tf = GaussianTF((Gaussian(0.1, 0.002, 0.5, RED), Gaussian(0.9, 0.002, 0.5, BLUE)))
    c = tf.color(np.array([0.3, 0.7]))  # all contributions underflow to zero
    assert np.isfinite(c).all()
    np.testing.assert_allclose(c[0], RED)
    np.testing.assert_allclose(c[1], BLUE)


def test_lut_shape_entries_and_sample_distance_correction():
    tf = two_peaks()
    lut = tf.lut(256)
    assert lut.shape == (256, 4) and lut.dtype == np.float32
    s = np.linspace(0, 1, 256)
    np.testing.assert_allclose(lut[:, 3], tf.opacity(s), atol=1e-6)
    np.testing.assert_allclose(lut[:, :3], tf.color(s), atol=1e-6)
    half = tf.lut(256, sample_distance=0.5)
    np.testing.assert_allclose(half[:, 3], 1 - (1 - tf.opacity(s)) ** 0.5, atol=1e-6)
    # Two half steps composite to exactly one full step.
    np.testing.assert_allclose(1 - (1 - half[:, 3]) ** 2, lut[:, 3], atol=1e-6)
    assert tf.lut(4096).shape == (4096, 4)


@pytest.mark.parametrize("size", [1, 0, 70000])
def test_lut_rejects_bad_size(size):
    with pytest.raises(TransferFunctionError):
        two_peaks().lut(size)


@pytest.mark.parametrize("d", [0.0, -1.0, float("nan")])
def test_lut_rejects_bad_sample_distance(d):
    with pytest.raises(TransferFunctionError):
        two_peaks().lut(64, sample_distance=d)


# -- editing --------------------------------------------------------------------------------
def test_freeze_unfreeze_only_and_sorted():
    tf = two_peaks()
    assert tf.frozen_mask().tolist() == [False, True]
    f = tf.freeze([1])
    assert f.frozen_mask().tolist() == [True, False]
    assert tf.frozen_mask().tolist() == [False, True]  # the original is unchanged
    assert not f.unfreeze().frozen_mask().any()
    one = tf.only(1)
    assert len(one) == 1 and one.gaussians[0].mean == 0.7
    rev = tf.with_gaussians(reversed(tf.gaussians))
    assert [g.mean for g in rev.sorted().gaussians] == [0.3, 0.7]


# -- JSON -----------------------------------------------------------------------------------
def test_json_round_trip_is_exact():
    rng = np.random.default_rng(3)
    gs = tuple(
        Gaussian(
            mean=float(rng.random()),
            width=float(rng.uniform(0.002, 0.5)),
            height=float(rng.random()),
            color=tuple(float(v) for v in rng.random(3)),
            frozen=bool(i % 2),
        )
        for i in range(7)
    )
    tf = GaussianTF(gs, value_range=(-1024.0, 3071.5), name="ct <bone>", metadata={"seed": 3})
    back = GaussianTF.from_json(tf.to_json())
    assert back == tf
    assert back.metadata == {"seed": 3}
    assert back.to_dict() == tf.to_dict()
    s = np.linspace(0, 1, 333)
    assert np.array_equal(back.lut(512), tf.lut(512))
    assert np.array_equal(back.color(s), tf.color(s))


@pytest.mark.parametrize(
    "text",
    [
        "{not json",
        "[]",
        '{"format": "something-else"}',
        '{"format": "intuitf.gaussian-tf", "version": 99, "gaussians": []}',
        '{"format": "intuitf.gaussian-tf", "version": 1}',
        '{"format": "intuitf.gaussian-tf", "version": 1, "gaussians": [{"mean": 0.5}]}',
        '{"format": "intuitf.gaussian-tf", "version": 1, "gaussians": [5]}',
        '{"format": "intuitf.gaussian-tf", "version": "x", "gaussians": []}',
        '{"format": "intuitf.gaussian-tf", "version": 1, "gaussians": '
        '[{"mean": "a", "width": 0.1, "height": 0.1, "color": [1, 1, 1]}]}',
        '{"format": "intuitf.gaussian-tf", "version": 1, "value_range": 3, "gaussians": '
        '[{"mean": 0.5, "width": 0.1, "height": 0.1, "color": [1, 1, 1]}]}',
    ],
)
def test_from_json_rejects_bad_documents_with_a_clear_error(text):
    with pytest.raises(TransferFunctionError) as info:
        GaussianTF.from_json(text)
    assert info.value.message


def test_save_and_load_round_trip(tmp_path):
    tf = two_peaks(value_range=(0.0, 255.0), name="two")
    p = save_tf(tf, tmp_path / "sub" / "tf.json")
    assert p.exists()
    assert json.loads(p.read_text())["format"] == "intuitf.gaussian-tf"
    assert load_tf(p) == tf
    assert not list((tmp_path / "sub").glob("*.tmp"))  # the atomic write left nothing behind


def test_load_tf_errors_name_the_file(tmp_path):
    with pytest.raises(TransferFunctionError, match="no such"):
        load_tf(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{oops")
    with pytest.raises(TransferFunctionError, match="bad.json"):
        load_tf(bad)
    binary = tmp_path / "bin.json"
    binary.write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(TransferFunctionError, match="bin.json"):
        load_tf(binary)
