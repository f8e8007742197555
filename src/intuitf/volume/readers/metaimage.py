"""MetaImage (``.mha``, or ``.mhd`` with its data file), through SimpleITK.

SimpleITK's array view is already ``[z, y, x]``; ``GetSpacing`` is along (x, y, z).
"""

from __future__ import annotations

import numpy as np
import SimpleITK as sitk

from intuitf.errors import VolumeError
from intuitf.volume.request import RawArray, ReadRequest

_PIXEL_DTYPES = {
    sitk.sitkUInt8: np.dtype("u1"),
    sitk.sitkInt8: np.dtype("i1"),
    sitk.sitkUInt16: np.dtype("u2"),
    sitk.sitkInt16: np.dtype("i2"),
    sitk.sitkUInt32: np.dtype("u4"),
    sitk.sitkInt32: np.dtype("i4"),
    sitk.sitkUInt64: np.dtype("u8"),
    sitk.sitkInt64: np.dtype("i8"),
    sitk.sitkFloat32: np.dtype("f4"),
    sitk.sitkFloat64: np.dtype("f8"),
}


def read(request: ReadRequest) -> RawArray:
    """Read a MetaImage file."""
    path = request.path
    reader = sitk.ImageFileReader()
    reader.SetFileName(str(path))
    try:
        reader.ReadImageInformation()
    except RuntimeError as exc:
        raise VolumeError(
            f"{path}: not a readable MetaImage header ({_first_line(exc)}).",
            "Check the header (and, for .mhd, that its ElementDataFile exists).",
        ) from None
    size = tuple(int(s) for s in reader.GetSize())
    if len(size) != 3 or reader.GetNumberOfComponents() != 1:
        raise VolumeError(
            f"{path}: expected a 3D scalar image, got size {size} with "
            f"{reader.GetNumberOfComponents()} component(s).",
            "Save a single 3D scalar channel.",
        )
    request.reserve(size, _PIXEL_DTYPES.get(reader.GetPixelID(), np.dtype("f8")))  # type: ignore[arg-type]
    try:
        img = reader.Execute()
    except RuntimeError as exc:
        raise VolumeError(
            f"{path}: the MetaImage voxel data is truncated or corrupt ({_first_line(exc)}).",
            "Check that the file (and its data file) is complete.",
        ) from None
    arr = sitk.GetArrayFromImage(img)  # [z, y, x]
    return RawArray(arr, spacing=tuple(float(s) for s in img.GetSpacing()))  # type: ignore[arg-type]


def _first_line(exc: Exception) -> str:
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    # ITK messages end with the useful part ("Description: ...").
    desc = [ln for ln in lines if ln.lower().startswith("description")]
    return (desc[-1] if desc else (lines[-1] if lines else type(exc).__name__))[:200]
