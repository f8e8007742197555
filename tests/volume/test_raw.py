"""Headerless raw and raw.gz files: names, shapes, byte order, and the errors users hit."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from intuitf.errors import VolumeError
from intuitf.volume import load_volume
from intuitf.volume.readers.raw import parse_name


def _ramp(dims_xyz, dtype):
    x, y, z = dims_xyz
    zz, yy, xx = np.meshgrid(np.arange(z), np.arange(y), np.arange(x), indexing="ij")
    return (xx + 10 * yy + 100 * zz).astype(dtype)


def test_parse_name_variants():
    assert parse_name("foot_256x256x256_uint8.raw.gz") == ((256, 256, 256), "uint8", "foot")
    assert parse_name("tooth_103x94x161_uint8.raw.gz") == ((103, 94, 161), "uint8", "tooth")
    assert parse_name("foot_zfp8lossy_256x256x256_uint8.raw.gz") == (
        (256, 256, 256),
        "uint8",
        "foot",
    )
    assert parse_name("scan.raw") == (None, None, "scan")


@pytest.mark.parametrize("order", ["little", "big"])
def test_raw_uint16_byte_orders_and_orientation(tmp_path, order):
    a = _ramp((7, 5, 3), np.uint16)
    p = tmp_path / "v.raw"
    a.astype(("<" if order == "little" else ">") + "u2").tofile(p)
    v = load_volume(p, shape=(7, 5, 3), dtype="uint16", byte_order=order, spacing=(1, 2, 3))
    assert v.shape == (3, 5, 7)  # [z, y, x]
    assert v.dims == (7, 5, 3)
    assert v.spacing == (1.0, 2.0, 3.0)
    assert v.original_dtype == "uint16"
    assert v.value_range == (0.0, 246.0)  # 6 + 40 + 200
    # x varies fastest in the file: voxel (x=6, y=0, z=2) holds 206.
    assert v.to_original(float(v.data[2, 0, 6])) == pytest.approx(206, abs=1e-3)
    assert v.lut_size == 256  # at least 256 entries, one per integer value above that


def test_raw_gz_from_name(tmp_path):
    a = _ramp((6, 4, 5), np.int16) - 300
    p = tmp_path / "thing_6x4x5_int16.raw.gz"
    p.write_bytes(gzip.compress(a.tobytes()))
    v = load_volume(p)
    assert v.name == "thing"
    assert v.shape == (5, 4, 6)
    assert v.original_dtype == "int16"
    assert v.value_range == (-300.0, float(a.max()))
    np.testing.assert_allclose(v.to_original(v.data), a, atol=1e-3)


def test_wrong_byte_order_gives_different_values(tmp_path):
    a = _ramp((4, 4, 4), np.uint16)
    p = tmp_path / "v_4x4x4_uint16.raw"
    a.astype(">u2").tofile(p)
    v = load_volume(p)  # read as little-endian: 1 becomes 256
    assert v.value_range[1] > 1000


def test_size_mismatch_suggests_matching_shapes(tmp_path):
    p = tmp_path / "v.raw"
    np.zeros((10, 8, 8), np.uint16).tofile(p)  # 1280 bytes
    with pytest.raises(VolumeError) as ei:
        load_volume(p, shape=(8, 8, 10), dtype="uint8")
    msg = str(ei.value)
    assert "640 bytes" in msg and "1280 bytes" in msg and str(p) in msg
    assert "--dtype uint16" in msg and "--shape 8,8,20" in msg


def test_gz_size_mismatch_and_truncation(tmp_path):
    p = tmp_path / "v_8x8x8_uint8.raw.gz"
    p.write_bytes(gzip.compress(np.arange(8 * 8 * 9, dtype=np.uint8).tobytes()))
    with pytest.raises(VolumeError, match="576 bytes"):
        load_volume(p)
    good = gzip.compress(np.arange(512, dtype=np.uint8).tobytes())
    q = tmp_path / "w_8x8x8_uint8.raw.gz"
    q.write_bytes(good[: len(good) // 2])
    with pytest.raises(VolumeError, match="corrupt or truncated|bytes"):
        load_volume(q)
    r = tmp_path / "x_8x8x8_uint8.raw.gz"
    r.write_bytes(b"this is not gzip at all, just text...")
    with pytest.raises(VolumeError, match=str(r.name)):
        load_volume(r)


def test_missing_shape_unknown_dtype_and_bad_byte_order(tmp_path):
    p = tmp_path / "scan.raw"
    p.write_bytes(bytes(64))
    with pytest.raises(VolumeError, match="--shape"):
        load_volume(p)
    with pytest.raises(VolumeError, match="unknown voxel type 'uint12'"):
        load_volume(p, shape=(4, 4, 4), dtype="uint12")
    with pytest.raises(VolumeError, match="byte order"):
        load_volume(p, shape=(4, 4, 4), dtype="uint8", byte_order="middle")


def test_constant_volume_is_refused(tmp_path):
    p = tmp_path / "flat_4x4x4_uint8.raw"
    np.full(64, 7, np.uint8).tofile(p)
    with pytest.raises(VolumeError, match="constant"):
        load_volume(p)


def test_nan_and_inf_are_noted_and_replaced(tmp_path):
    a = np.linspace(0, 1, 64, dtype=np.float32)
    a[3] = np.nan
    a[10] = np.inf
    p = tmp_path / "f_4x4x4_float32.raw"
    a.tofile(p)
    v = load_volume(p)
    assert np.isfinite(v.data).all()
    assert any("2 NaN/Inf" in n for n in v.notes)
    w = load_volume(p, max_dim=2)  # the downsampling path handles them too
    assert np.isfinite(w.data).all() and any("NaN/Inf" in n for n in w.notes)


def test_missing_file_and_unknown_extension(tmp_path):
    with pytest.raises(VolumeError, match="no such file"):
        load_volume(tmp_path / "nope.raw")
    q = tmp_path / "volume.xyz"
    q.write_bytes(b"123")
    with pytest.raises(VolumeError, match="unknown volume format") as ei:
        load_volume(q)
    assert ".nrrd" in str(ei.value)


def test_too_large_for_memory_suggests_max_dim(tmp_path, monkeypatch):
    p = tmp_path / "big_64x64x64_uint16.raw"
    np.zeros(64**3, np.uint16).tofile(p)
    monkeypatch.setattr("intuitf.volume.request.available_memory_bytes", lambda: 1 << 20)
    with pytest.raises(VolumeError, match="--max-dim") as ei:
        load_volume(p)
    assert "available" in str(ei.value)
    # Memory-mapped raw files downsample in slabs, so a small max_dim fits.
    a = np.zeros((64, 64, 64), np.uint16)
    a[20:40, 10:50, 5:60] = 1000
    a.tofile(p)
    v = load_volume(p, max_dim=16)
    assert v.dims == (16, 16, 16)


def test_max_dim_keeps_extent_and_range(tmp_path):
    a = _ramp((40, 20, 10), np.uint16)
    p = tmp_path / "r_40x20x10_uint16.raw"
    a.tofile(p)
    v = load_volume(p, spacing=(1.0, 1.0, 2.0), max_dim=20)
    assert v.dims == (20, 10, 5)
    assert v.extent == pytest.approx((39.0, 19.0, 18.0))
    assert v.value_range == (0.0, float(a.max()))
    assert v.original_dtype == "uint16"
    assert any("Downsampled from 40x20x10 to 20x10x5" in n for n in v.notes)
    # A linear ramp stays a ramp: the mean is kept.
    assert v.to_original(float(v.data.mean())) == pytest.approx(a.mean(), rel=0.02)
