"""A DICOM CT series built with pydicom: slice order, rescaling and spacing."""

from __future__ import annotations

import numpy as np
import pytest
from pydicom.dataset import FileDataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

from intuitf.errors import VolumeError
from intuitf.volume import load_volume

ROWS, COLS, SLICES = 6, 8, 5  # y, x, z
PIXEL = (0.7, 0.6)  # (row spacing = y, column spacing = x)
DZ = 2.5


def _stored() -> np.ndarray:
    z, y, x = np.meshgrid(np.arange(SLICES), np.arange(ROWS), np.arange(COLS), indexing="ij")
    return (x + 10 * y + 100 * z + 500).astype(np.uint16)  # [z, y, x]


def _write_series(folder, stored, *, slope=1.0, intercept=-1024.0, series_uid=None, prefix="img"):
    folder.mkdir(exist_ok=True)
    series_uid = series_uid or generate_uid()
    study = generate_uid()
    for k in range(stored.shape[0]):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = FileDataset(None, {}, file_meta=meta, preamble=b"\0" * 128)
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.StudyInstanceUID = study
        ds.SeriesInstanceUID = series_uid
        ds.Modality = "CT"
        ds.Rows, ds.Columns = stored.shape[1], stored.shape[2]
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit = 16, 12, 11
        ds.PixelRepresentation = 0
        ds.PixelSpacing = list(PIXEL)
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
        ds.ImagePositionPatient = [-10.0, -20.0, 30.0 + k * DZ]
        # Instance numbers run backwards and file names are shuffled: only the position
        # along the slice normal gives the right order.
        ds.InstanceNumber = stored.shape[0] - k
        ds.RescaleSlope = slope
        ds.RescaleIntercept = intercept
        ds.PixelData = stored[k].tobytes()
        ds.save_as(
            folder / f"{prefix}_{(k * 3) % stored.shape[0]}_{k}.dcm", enforce_file_format=True
        )


def test_ct_series_sorted_rescaled_and_spaced(tmp_path):
    stored = _stored()
    _write_series(tmp_path / "ct", stored)
    (tmp_path / "ct" / "README.txt").write_text("not a DICOM file")
    v = load_volume(tmp_path / "ct")
    assert v.shape == (SLICES, ROWS, COLS)
    assert v.spacing == pytest.approx((PIXEL[1], PIXEL[0], DZ))
    hu = stored.astype(np.int32) - 1024
    assert v.original_dtype == "int16"
    assert v.value_range == (float(hu.min()), float(hu.max()))
    np.testing.assert_allclose(v.to_original(v.data), hu, atol=0.01)


def test_fractional_slope_gives_float_values(tmp_path):
    stored = _stored()
    _write_series(tmp_path / "ct", stored, slope=0.5, intercept=-10.0)
    v = load_volume(tmp_path / "ct")
    assert v.original_dtype == "float32"
    np.testing.assert_allclose(v.to_original(v.data), stored * 0.5 - 10, atol=0.01)


def test_single_file_reads_its_series_and_largest_series_wins(tmp_path):
    stored = _stored()
    _write_series(tmp_path / "ct", stored)
    _write_series(
        tmp_path / "ct", stored[:2] + 7, prefix="other"
    )  # a second, smaller series in the folder
    big = load_volume(tmp_path / "ct")
    assert big.shape[0] == SLICES and any("2 series" in n for n in big.notes)
    small = load_volume(tmp_path / "ct" / "other_0_0.dcm")
    assert small.shape[0] == 2
    assert small.value_range[0] == big.value_range[0] + 7


def test_folder_without_dicom_images(tmp_path):
    d = tmp_path / "empty"
    d.mkdir()
    (d / "notes.txt").write_text("hello")
    with pytest.raises(VolumeError, match="no DICOM images") as ei:
        load_volume(d)
    assert str(d) in str(ei.value)
