"""NIfTI-1/2 (``.nii``, ``.nii.gz``), through nibabel.

NIfTI's first index is x; the array is transposed to ``[z, y, x]``. Spacing comes from the
header's voxel sizes (``pixdim``). Scaling (``scl_slope``/``scl_inter``) is applied when the file
sets it. A 4D file with several volumes gives its first volume, with a note.
"""

from __future__ import annotations

import zlib

import nibabel as nib
import numpy as np

from intuitf.errors import VolumeError
from intuitf.volume.request import RawArray, ReadRequest


def read(request: ReadRequest) -> RawArray:
    """Read a NIfTI file."""
    path = request.path
    try:
        img = nib.load(str(path))
    except (nib.filebasedimages.ImageFileError, EOFError, OSError, ValueError) as exc:
        raise VolumeError(
            f"{path}: not a readable NIfTI file ({exc}).",
            "Check that the file is complete and really NIfTI.",
        ) from None
    shape = tuple(int(s) for s in img.shape)
    notes: list[str] = []
    while len(shape) > 3 and shape[-1] == 1:
        shape = shape[:-1]
    if len(shape) < 3:
        raise VolumeError(f"{path}: expected a 3D volume, got shape {img.shape}.")
    if len(shape) > 3:
        notes.append(f"The file holds {int(np.prod(shape[3:]))} volumes; using the first.")
    hdr = img.header
    slope, inter = hdr.get_slope_inter()
    scaled = slope is not None and (slope != 1 or (inter or 0) != 0)
    dtype = np.dtype("f8") if scaled else hdr.get_data_dtype()
    request.reserve(shape[:3], dtype)  # type: ignore[arg-type]
    try:
        proxy = img.dataobj
        index = (slice(None),) * 3 + (0,) * (len(img.shape) - 3)
        xyz = np.asanyarray(proxy[index] if len(img.shape) > 3 else proxy)
    except (EOFError, OSError, ValueError, zlib.error) as exc:
        raise VolumeError(
            f"{path}: the NIfTI voxel data is truncated or corrupt ({exc}).",
            "Check that the file is complete.",
        ) from None
    zooms = [float(z) for z in hdr.get_zooms()[:3]]
    spacing = tuple(zooms) if all(z > 0 for z in zooms) else None
    return RawArray(np.ascontiguousarray(xyz.transpose(2, 1, 0)), spacing=spacing, notes=notes)  # type: ignore[arg-type]
