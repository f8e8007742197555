"""NRRD (``.nrrd``) and detached-header NRRD (``.nhdr``) files, through pynrrd.

NRRD's first axis varies fastest and is x; the array is read in C order so it comes out
``[z, y, x]``. Spacing comes from ``spacings`` or from the lengths of ``space directions``.
"""

from __future__ import annotations

import nrrd
import numpy as np

from intuitf.errors import VolumeError
from intuitf.volume.request import RawArray, ReadRequest


def _spacing(header: dict) -> tuple[float, float, float] | None:
    if "spacings" in header:
        sp = [float(s) for s in header["spacings"]]
        if len(sp) == 3 and all(np.isfinite(s) and s > 0 for s in sp):
            return tuple(sp)  # type: ignore[return-value]
    dirs = header.get("space directions")
    if dirs is not None:
        rows = [r for r in dirs if r is not None and np.all(np.isfinite(np.asarray(r, float)))]
        if len(rows) == 3:
            sp = [float(np.linalg.norm(np.asarray(r, float))) for r in rows]
            if all(s > 0 for s in sp):
                return tuple(sp)  # type: ignore[return-value]
    return None


def read(request: ReadRequest) -> RawArray:
    """Read an NRRD or NHDR file."""
    path = request.path
    try:
        header = nrrd.read_header(str(path))
    except StopIteration:  # pynrrd runs out of lines: an empty or cut-off header
        raise VolumeError(
            f"{path}: the NRRD header ends before its first line is complete (empty file?).",
            "Check that the file is a complete NRRD file.",
        ) from None
    except nrrd.NRRDError as exc:
        raise VolumeError(
            f"{path}: not a valid NRRD header ({exc}).",
            "Check that the file is a complete NRRD file.",
        ) from None
    sizes = [int(s) for s in header.get("sizes", [])]
    notes: list[str] = []
    if len(sizes) != 3:
        raise VolumeError(
            f"{path}: expected a 3D scalar NRRD, got {len(sizes)} axes of sizes {sizes}.",
            "Save a single 3D scalar channel.",
        )
    try:
        dtype = nrrd.reader._determine_datatype(header)  # the header's declared sample type
    except Exception:  # older/newer pynrrd: fall back to a conservative estimate
        dtype = np.dtype("f8")
    request.reserve(tuple(sizes), dtype)  # type: ignore[arg-type]
    try:
        data, header = nrrd.read(str(path), index_order="C")
    except (nrrd.NRRDError, StopIteration) as exc:
        raise VolumeError(
            f"{path}: the NRRD data could not be read ({exc}).",
            "Check that the file (and a detached data file) is complete.",
        ) from None
    return RawArray(np.asarray(data), spacing=_spacing(header), notes=notes)
