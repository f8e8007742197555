"""Every supported format is read with the right values, orientation and spacing.

Test files are written with the library that owns each format. The reference array ``REF`` is
``[z, y, x]`` with distinct sizes along each axis, and its values encode their position, so a
swapped or flipped axis cannot pass.
"""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.errors import VolumeError
from intuitf.volume import load_volume

NX, NY, NZ = 9, 7, 5
SPACING = (0.5, 0.75, 2.0)


def _ref(dtype=np.int16) -> np.ndarray:
    z, y, x = np.meshgrid(np.arange(NZ), np.arange(NY), np.arange(NX), indexing="ij")
    return (x + 10 * y + 100 * z - 50).astype(dtype)


REF = _ref()


def _check(v, ref=REF, spacing=SPACING, dtype=None):
    assert v.shape == (NZ, NY, NX)
    assert v.spacing == pytest.approx(spacing)
    assert v.original_dtype == (dtype or ref.dtype.name)
    assert v.value_range == (float(ref.min()), float(ref.max()))
    np.testing.assert_allclose(v.to_original(v.data), ref, atol=1e-3 * float(np.ptp(ref)))


def test_nrrd(tmp_path):
    import nrrd

    p = tmp_path / "v.nrrd"
    # pynrrd's default (Fortran) order takes the array indexed [x, y, z].
    nrrd.write(str(p), REF.transpose(2, 1, 0).copy(), {"spacings": list(SPACING)})
    _check(load_volume(p))
    q = tmp_path / "w.nrrd"
    hdr = {"space": "left-posterior-superior", "space directions": np.diag(SPACING)}
    nrrd.write(str(q), REF, header=hdr, index_order="C")
    _check(load_volume(q))


def test_nhdr_detached(tmp_path):
    import nrrd

    p = tmp_path / "v.nhdr"
    nrrd.write(str(p), REF, {"spacings": list(SPACING)}, detached_header=True, index_order="C")
    _check(load_volume(p))


@pytest.mark.parametrize("suffix", [".nii", ".nii.gz"])
def test_nifti(tmp_path, suffix):
    import nibabel as nib

    img = nib.Nifti1Image(REF.transpose(2, 1, 0).copy(), np.diag([*SPACING, 1.0]))
    img.header.set_zooms(SPACING)
    p = tmp_path / f"v{suffix}"
    nib.save(img, str(p))
    v = load_volume(p)
    _check(v)
    assert v.name == "v"


def test_nifti_4d_takes_first_volume(tmp_path):
    import nibabel as nib

    four = np.stack([REF.transpose(2, 1, 0), REF.transpose(2, 1, 0) * 0], axis=-1)
    img = nib.Nifti1Image(four, np.diag([*SPACING, 1.0]))
    p = tmp_path / "t.nii.gz"
    nib.save(img, str(p))
    v = load_volume(p)
    _check(v)
    assert any("using the first" in n for n in v.notes)


@pytest.mark.parametrize("suffix", [".mha", ".mhd"])
def test_metaimage(tmp_path, suffix):
    import SimpleITK as sitk

    img = sitk.GetImageFromArray(REF)  # SimpleITK's array view is [z, y, x]
    img.SetSpacing(SPACING)
    p = tmp_path / f"v{suffix}"
    sitk.WriteImage(img, str(p), useCompression=suffix == ".mha")
    _check(load_volume(p))


def test_numpy_npy_and_npz(tmp_path):
    p = tmp_path / "v.npy"
    np.save(p, REF)
    _check(load_volume(p, spacing=SPACING))
    q = tmp_path / "v.npz"
    np.savez_compressed(q, data=REF, spacing=np.array(SPACING))
    _check(load_volume(q))
    r = tmp_path / "many.npz"
    np.savez(r, a=REF, b=REF)
    with pytest.raises(VolumeError, match="'data' or 'volume'"):
        load_volume(r)


def test_multipage_tiff_with_imagej_spacing(tmp_path):
    import tifffile

    p = tmp_path / "stack.tif"
    ref = _ref(np.uint16) + 100
    tifffile.imwrite(
        p,
        ref,
        imagej=True,
        resolution=(1 / SPACING[0], 1 / SPACING[1]),
        metadata={"spacing": SPACING[2], "unit": "mm", "axes": "ZYX"},
    )
    _check(load_volume(p), ref=ref)


def test_tiff_slice_folder_in_natural_order(tmp_path):
    import tifffile

    d = tmp_path / "slices"
    d.mkdir()
    ref = _ref(np.uint16) + 100
    for k in range(NZ):  # names sort wrongly as text: s10 would come before s2
        tifffile.imwrite(d / f"s{k * 5}.tif", ref[k])
    _check(load_volume(d, spacing=SPACING), ref=ref)


def test_cvol_round_trip_and_compressed_refusal(tmp_path):
    from intuitf.volume.readers.cvol import write_cvol

    ref = _ref(np.uint16) + 100
    p = tmp_path / "v.cvol"
    write_cvol(p, ref, SPACING)
    raw = p.read_bytes()
    assert raw[:4] == b"cvol" and len(raw) == 64 + ref.nbytes
    assert int.from_bytes(raw[4:12], "little") == NX  # sizeX first
    _check(load_volume(p), ref=ref)
    f = tmp_path / "f.cvol"
    write_cvol(f, (ref / ref.max()).astype(np.float32), SPACING)
    assert load_volume(f).original_dtype == "float32"
    c = tmp_path / "c.cvol"
    c.write_bytes(raw[:56] + b"\x01" + raw[57:])
    with pytest.raises(VolumeError, match="LZ4-chunked") as ei:
        load_volume(c)
    assert "uncompressed" in str(ei.value)
    t = tmp_path / "t.cvol"
    t.write_bytes(raw[:200])
    with pytest.raises(VolumeError, match="truncated"):
        load_volume(t)
