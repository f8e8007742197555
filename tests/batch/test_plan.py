"""Which volumes a batch covers: files, folders, globs, DICOM series, missing paths."""

from __future__ import annotations

import numpy as np
import pytest
from pydicom.dataset import FileDataset, FileMetaDataset
from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

from intuitf.batch.plan import plan_volumes
from intuitf.errors import IntuitfError
from intuitf.volume import load_volume


def _write_series(folder, slices: int, value: int, description: str) -> None:
    folder.mkdir(exist_ok=True)
    series, study = generate_uid(), generate_uid()
    for k in range(slices):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = FileDataset(None, {}, file_meta=meta, preamble=b"\0" * 128)
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.StudyInstanceUID, ds.SeriesInstanceUID = study, series
        ds.SeriesDescription = description
        ds.Modality = "CT"
        ds.Rows, ds.Columns = 6, 8
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit = 16, 12, 11
        ds.PixelRepresentation = 0
        ds.PixelSpacing = [0.7, 0.6]
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
        ds.ImagePositionPatient = [0.0, 0.0, 2.0 * k]
        ds.InstanceNumber = k + 1
        ds.PixelData = (np.arange(48, dtype=np.uint16).reshape(6, 8) + value + k).tobytes()
        ds.save_as(folder / f"{description}_{k}.dcm", enforce_file_format=True)


def test_files_folders_globs_and_missing_paths(tmp_path):
    a = tmp_path / "scans"
    (a / "sub").mkdir(parents=True)
    for p in (a / "knee1.npy", a / "knee2.npy", a / "sub" / "knee1.npy"):
        np.save(p, np.zeros((4, 4, 4), np.uint8))
    (a / "notes.txt").write_text("not a volume")
    items = plan_volumes([str(a), str(tmp_path / "gone.nii.gz"), "phantom"])
    keys = [i.key for i in items]
    assert len(items) == 5
    # Two files share the stem "knee1": both get a stable, distinct key.
    assert sum(k.startswith("knee1-") for k in keys) == 2 and "knee2" in keys
    assert {i.kind for i in items} == {"file", "missing", "phantom"}
    assert plan_volumes([str(a), str(tmp_path / "gone.nii.gz"), "phantom"]) == items  # stable
    glob_items = plan_volumes([str(a / "knee*.npy")])
    assert [i.key for i in glob_items] == ["knee1", "knee2"]
    with pytest.raises(IntuitfError, match="no file or folder matches"):
        plan_volumes([str(tmp_path / "*.nrrd")])


def test_a_dicom_folder_of_several_series_is_one_volume_per_series(tmp_path):
    study = tmp_path / "study"
    _write_series(study, 5, 100, "soft")
    _write_series(study, 3, 900, "bone")
    items = plan_volumes([str(study)])
    assert [i.kind for i in items] == ["dicom-series", "dicom-series"]
    assert sorted(i.key for i in items) == ["study-bone", "study-soft"]
    depth = {i.key: load_volume(i.source).shape[0] for i in items}
    assert depth == {"study-soft": 5, "study-bone": 3}
