"""VTK XML image data (.vti), written by VTK's own writer in every mode and read without VTK."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.errors import VolumeError
from intuitf.volume import load_volume

from .test_formats import NX, NY, NZ, SPACING, _check, _ref

vtk = pytest.importorskip("vtk", reason="vtk is a test dependency for .vti files")


def _vtk_image(ref: np.ndarray, spacing=SPACING, extra_array=True):
    from vtk.util import numpy_support as ns

    img = vtk.vtkImageData()
    img.SetDimensions(NX, NY, NZ)
    img.SetSpacing(*spacing)
    if extra_array:  # a first, non-scalar array makes appended offsets non-zero
        other = ns.numpy_to_vtk(np.zeros(ref.size, np.float64), deep=True)
        other.SetName("other")
        img.GetPointData().AddArray(other)
    arr = ns.numpy_to_vtk(ref.ravel(), deep=True)
    arr.SetName("density")
    img.GetPointData().SetScalars(arr)
    return img


@pytest.mark.parametrize(
    ("mode", "compressor", "encode", "header"),
    [
        ("ascii", "none", True, 32),
        ("binary", "none", True, 32),
        ("binary", "zlib", True, 64),
        ("binary", "lz4", True, 32),
        ("appended", "none", False, 64),
        ("appended", "zlib", False, 32),
        ("appended", "lzma", False, 64),
        ("appended", "none", True, 32),
        ("appended", "zlib", True, 64),
    ],
)
def test_vti_every_mode(tmp_path, mode, compressor, encode, header):
    ref = _ref(np.int16)
    w = vtk.vtkXMLImageDataWriter()
    p = tmp_path / "v.vti"
    w.SetFileName(str(p))
    w.SetInputData(_vtk_image(ref))
    {"ascii": w.SetDataModeToAscii, "binary": w.SetDataModeToBinary,
     "appended": w.SetDataModeToAppended}[mode]()  # fmt: skip
    w.SetEncodeAppendedData(encode)
    {"none": w.SetCompressorTypeToNone, "zlib": w.SetCompressorTypeToZLib,
     "lz4": w.SetCompressorTypeToLZ4, "lzma": w.SetCompressorTypeToLZMA}[compressor]()  # fmt: skip
    w.SetHeaderTypeToUInt64() if header == 64 else w.SetHeaderTypeToUInt32()
    w.SetBlockSize(64)  # several compressed blocks, including a short last one
    assert w.Write() == 1
    _check(load_volume(p))


def test_vti_truncated_is_a_volume_error(tmp_path):
    w = vtk.vtkXMLImageDataWriter()
    p = tmp_path / "v.vti"
    w.SetFileName(str(p))
    w.SetInputData(_vtk_image(_ref(np.int16)))
    w.SetDataModeToAppended()
    w.SetEncodeAppendedData(False)
    w.SetCompressorTypeToZLib()
    w.Write()
    data = p.read_bytes()
    p.write_bytes(data[: len(data) - 300])
    with pytest.raises(VolumeError, match="corrupt or truncated|not a readable"):
        load_volume(p)
