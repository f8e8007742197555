"""Broken, truncated, empty or oversized inputs of every format give one clear VolumeError."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from intuitf.errors import VolumeError
from intuitf.volume import load_volume

A = (np.arange(6 * 5 * 4).reshape(4, 5, 6) * 3).astype(np.int16)


def _truncate(p, keep: float = 0.5):
    data = p.read_bytes()
    p.write_bytes(data[: int(len(data) * keep)])


def _assert_clear(p, match=None):
    with pytest.raises(VolumeError) as ei:
        load_volume(p)
    msg = str(ei.value)
    assert str(p.name) in msg and "What to do" in msg
    if match:
        assert any(m in msg for m in match), msg
    return msg


def test_corrupt_nrrd_header(tmp_path):
    p = tmp_path / "v.nrrd"
    p.write_bytes(b"NRRD0004\ntype: banana\ndimension: 3\n\n")
    _assert_clear(p, ["NRRD"])


def test_truncated_nrrd_data(tmp_path):
    import nrrd

    p = tmp_path / "v.nrrd"
    nrrd.write(str(p), A, index_order="C")
    _truncate(p, 0.8)
    _assert_clear(p, ["truncated", "corrupt", "could not be read"])


def test_truncated_nifti(tmp_path):
    import nibabel as nib

    p = tmp_path / "v.nii.gz"
    nib.save(nib.Nifti1Image(A.transpose(2, 1, 0).copy(), np.eye(4)), str(p))
    _truncate(p, 0.6)
    _assert_clear(p, ["NIfTI", "truncated"])
    q = tmp_path / "text.nii"
    q.write_text("not nifti")
    _assert_clear(q, ["NIfTI"])


def test_corrupt_metaimage(tmp_path):
    p = tmp_path / "v.mhd"
    p.write_text("ObjectType = Image\nNDims = 3\nDimSize = 4 4 4\nElementType = MET_UCHAR\n"
                 "ElementDataFile = missing.raw\n")  # fmt: skip
    _assert_clear(p, ["MetaImage"])


def test_corrupt_tiff_and_npy_and_npz(tmp_path):
    t = tmp_path / "v.tif"
    t.write_bytes(b"II*\x00garbage")
    _assert_clear(t, ["TIFF"])
    n = tmp_path / "v.npy"
    np.save(n, A)
    _truncate(n, 0.5)
    _assert_clear(n, ["npy", "truncated", "corrupt"])
    z = tmp_path / "v.npz"
    z.write_bytes(b"PK\x03\x04 not really a zip")
    _assert_clear(z, ["npz", "corrupt", "could not be read"])


def test_2d_and_empty_arrays(tmp_path):
    p = tmp_path / "flat.npy"
    np.save(p, np.zeros((4, 4), np.uint8))
    _assert_clear(p, ["3D"])
    e = tmp_path / "empty.npy"
    np.save(e, np.zeros((0, 4, 4), np.uint8))
    with pytest.raises(VolumeError, match="empty"):
        load_volume(e)


def test_constant_and_all_nan(tmp_path):
    p = tmp_path / "c.npy"
    np.save(p, np.full((3, 3, 3), 5.0, np.float32))
    with pytest.raises(VolumeError, match="constant"):
        load_volume(p)
    q = tmp_path / "n.npy"
    np.save(q, np.full((3, 3, 3), np.nan, np.float32))
    with pytest.raises(VolumeError, match="NaN"):
        load_volume(q)


def test_bad_cvol_magic(tmp_path):
    p = tmp_path / "v.cvol"
    p.write_bytes(b"nope" + bytes(100))
    _assert_clear(p, ["magic"])


def test_too_large_header_formats(tmp_path, monkeypatch):
    import nrrd

    p = tmp_path / "v.nrrd"
    nrrd.write(str(p), np.zeros((40, 40, 40), np.float32), index_order="C")
    monkeypatch.setattr("intuitf.volume.request.available_memory_bytes", lambda: 200_000)
    msg = _assert_clear(p, ["--max-dim"])
    assert "40x40x40 float32" in msg
    # Formats read whole cannot be helped by --max-dim alone: the hint says so.
    with pytest.raises(VolumeError, match="read whole"):
        load_volume(p, max_dim=8)


def test_wrong_shape_on_gz_is_caught_before_decompressing(tmp_path):
    p = tmp_path / "v.raw.gz"
    p.write_bytes(gzip.compress(bytes(1000)))
    with pytest.raises(VolumeError, match="1000 bytes"):
        load_volume(p, shape=(10, 10, 11), dtype="uint8")
