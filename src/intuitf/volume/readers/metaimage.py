"""MetaImage (``.mha``, or ``.mhd`` with its data file), through SimpleITK.

SimpleITK's array view is already ``[z, y, x]``; ``GetSpacing`` is along (x, y, z).
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
from collections.abc import Iterator

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
    """Read a MetaImage file.

    ITK's own messages (MetaIO prints to the process's standard error from C++) are captured,
    not shown, and the useful one becomes part of our message.
    """
    path = request.path
    reader = sitk.ImageFileReader()
    reader.SetFileName(str(path))
    with _captured_stderr() as said:
        try:
            reader.ReadImageInformation()
            error = None
        except RuntimeError as exc:
            error = exc
    if error is not None:
        raise VolumeError(
            f"{path}: not a readable MetaImage header ({_reason(error, said)}).",
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
    with _captured_stderr() as said:
        try:
            img = reader.Execute()
            error = None
        except RuntimeError as exc:
            error = exc
    if error is not None:
        raise VolumeError(
            f"{path}: the MetaImage voxel data is truncated or corrupt ({_reason(error, said)}).",
            "Check that the file (and its data file) is complete.",
        ) from None
    arr = sitk.GetArrayFromImage(img)  # [z, y, x]
    return RawArray(arr, spacing=tuple(float(s) for s in img.GetSpacing()))  # type: ignore[arg-type]


@contextlib.contextmanager
def _captured_stderr() -> Iterator[list[str]]:
    """Send file descriptor 2 to a temporary file for the block; yield a list that holds the
    text written there once the block ends (C++ libraries write to it directly)."""
    said: list[str] = []
    try:
        fd = sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        fd = 2
    try:
        saved = os.dup(fd)
    except OSError:  # no standard error to redirect: nothing will be shown anyway
        yield said
        return
    with tempfile.TemporaryFile() as tmp:
        with contextlib.suppress(AttributeError, OSError, ValueError):
            sys.stderr.flush()
        os.dup2(tmp.fileno(), fd)
        try:
            yield said
        finally:
            os.dup2(saved, fd)
            os.close(saved)
            tmp.seek(0)
            said.extend(
                ln.strip()
                for ln in tmp.read().decode("utf-8", "replace").splitlines()
                if ln.strip()
            )


def _reason(exc: Exception, said: list[str]) -> str:
    """The useful part of an ITK error: MetaIO's own complaint if it made one, else the
    exception's description. ITK's "Reason: ..." line is the C library's last errno, which
    has nothing to do with a corrupt file ("No such file or directory"), so it is left out."""
    meta = [ln.removeprefix("MetaImage:").strip() for ln in said]
    meta = [ln for ln in meta if ln]
    if meta:
        return "; ".join(meta)[:200]
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    lines = [ln for ln in lines if not ln.lower().startswith("reason:")]
    desc = [ln for ln in lines if ln.lower().startswith("description")]
    if desc:
        return desc[-1][:200]
    err = [re.sub(r"^.*?ERROR:\s*(\w+\(0x[0-9a-f]+\):\s*)?", "", ln) for ln in lines]
    return (err[-1] if err else type(exc).__name__)[:200]
