"""A DICOM series (a folder of single-slice files), through pydicom.

Slices are ordered by their position along the slice normal (``ImagePositionPatient`` projected
on the cross product of the ``ImageOrientationPatient`` row and column directions), falling back
to ``InstanceNumber``. Stored values are rescaled with ``RescaleSlope``/``RescaleIntercept``
(Hounsfield units for CT). Spacing: ``PixelSpacing`` gives (row, column) = (y, x); z is the
median distance between slice positions. Rows run along y and columns along x, so the stack is
``[z, y, x]``. If the folder holds several series, the one with the most slices is read.
A path to one file reads the series that file belongs to, from its folder.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np
import pydicom
from pydicom.errors import InvalidDicomError

from intuitf.errors import VolumeError
from intuitf.volume.request import RawArray, ReadRequest


def _headers(folder: Path) -> list[tuple[Path, pydicom.Dataset]]:
    """DICOM image headers (no pixels) of the files in ``folder``, skipping non-DICOM files."""
    out = []
    for p in sorted(folder.iterdir()):
        if not p.is_file() or p.name.startswith("."):
            continue
        try:
            ds = pydicom.dcmread(p, stop_before_pixels=True)
        except (InvalidDicomError, OSError, EOFError, ValueError, TypeError, AttributeError):
            continue
        if "Rows" in ds and "Columns" in ds:
            out.append((p, ds))
    return out


def _position(ds: pydicom.Dataset, normal: np.ndarray | None) -> float | None:
    pos = ds.get("ImagePositionPatient")
    if pos is None or normal is None:
        return None
    return float(np.dot(np.asarray([float(v) for v in pos]), normal))


def _normal(ds: pydicom.Dataset) -> np.ndarray | None:
    iop = ds.get("ImageOrientationPatient")
    if iop is None or len(iop) != 6:
        return None
    r = np.asarray([float(v) for v in iop[:3]])
    c = np.asarray([float(v) for v in iop[3:]])
    n = np.cross(r, c)
    return n / np.linalg.norm(n) if np.linalg.norm(n) > 0 else None


def read(request: ReadRequest) -> RawArray:
    """Read the DICOM series in a folder (or the series of one file)."""
    path = request.path
    folder = path if path.is_dir() else path.parent
    headers = _headers(folder)
    if not path.is_dir():
        try:
            uid = pydicom.dcmread(path, stop_before_pixels=True).get("SeriesInstanceUID")
        except (InvalidDicomError, OSError, EOFError, ValueError) as exc:
            raise VolumeError(
                f"{path}: not a readable DICOM file ({exc}).", "Check the file."
            ) from None
        headers = [(p, ds) for p, ds in headers if ds.get("SeriesInstanceUID") == uid]
    if not headers:
        raise VolumeError(
            f"{folder}: no DICOM images found in this folder.",
            "Point at the folder that holds the series' .dcm files (one file per slice), or "
            "use another supported format.",
        )
    notes: list[str] = []
    series: dict[str, list[tuple[Path, pydicom.Dataset]]] = defaultdict(list)
    for p, ds in headers:
        series[str(ds.get("SeriesInstanceUID", ""))].append((p, ds))
    if len(series) > 1:
        notes.append(f"The folder holds {len(series)} series; reading the largest.")
    items = max(series.values(), key=len)
    rows, cols = int(items[0][1].Rows), int(items[0][1].Columns)
    items = [(p, ds) for p, ds in items if (int(ds.Rows), int(ds.Columns)) == (rows, cols)]
    if len(items) < 2:
        raise VolumeError(
            f"{folder}: the DICOM series has only one slice; a volume needs several.",
            "Point at a folder holding every slice of the series.",
        )
    normal = _normal(items[0][1])
    positions = [_position(ds, normal) for _, ds in items]
    if all(v is not None for v in positions):
        order = np.argsort(positions, kind="stable")
    else:
        order = np.argsort([int(ds.get("InstanceNumber", 0)) for _, ds in items], kind="stable")
        notes.append("Slices have no position; ordered by InstanceNumber.")
    items = [items[i] for i in order]

    ds0 = items[0][1]
    slope = float(ds0.get("RescaleSlope", 1) or 1)
    inter = float(ds0.get("RescaleIntercept", 0) or 0)
    out_dtype = _output_dtype(ds0, slope, inter)
    request.reserve((cols, rows, len(items)), out_dtype)
    stack = np.empty((len(items), rows, cols), dtype=out_dtype)
    for k, (p, _) in enumerate(items):
        try:
            ds = pydicom.dcmread(p)
            px = ds.pixel_array
        except Exception as exc:  # pixel decoding raises many types (missing codec, bad data)
            raise VolumeError(
                f"{p}: the slice's pixel data could not be decoded ({exc}).",
                "Check the file; compressed transfer syntaxes may need pylibjpeg or gdcm.",
            ) from None
        s = float(ds.get("RescaleSlope", 1) or 1)
        i = float(ds.get("RescaleIntercept", 0) or 0)
        stack[k] = px.astype(np.float64) * s + i if (s, i) != (1.0, 0.0) else px

    spacing = _spacing(items, positions=[positions[i] for i in order], notes=notes)
    return RawArray(stack, spacing=spacing, notes=notes)


def _output_dtype(ds: pydicom.Dataset, slope: float, inter: float) -> np.dtype:
    """The narrowest type that holds rescaled values exactly (int16 for most CT)."""
    bits = int(ds.get("BitsStored", ds.get("BitsAllocated", 16)))
    signed = int(ds.get("PixelRepresentation", 0)) == 1
    lo = -(2 ** (bits - 1)) if signed else 0
    hi = 2 ** (bits - 1) - 1 if signed else 2**bits - 1
    if slope != int(slope) or inter != int(inter):
        return np.dtype("f4") if bits <= 16 else np.dtype("f8")
    vals = [lo * slope + inter, hi * slope + inter]
    lo2, hi2 = min(vals), max(vals)
    for t in ("u1", "i1", "u2", "i2", "u4", "i4"):
        info = np.iinfo(t)
        if info.min <= lo2 and hi2 <= info.max:
            return np.dtype(t)
    return np.dtype("i8")


def _spacing(items, positions, notes: list[str]) -> tuple[float, float, float] | None:
    ds0 = items[0][1]
    ps = ds0.get("PixelSpacing")
    if ps is None or len(ps) != 2:
        notes.append("No PixelSpacing; in-plane spacing taken as 1.")
        sy, sx = 1.0, 1.0
    else:
        sy, sx = float(ps[0]), float(ps[1])
    if all(p is not None for p in positions):
        gaps = np.diff(np.asarray(positions, dtype=float))
        sz = float(np.median(gaps))
        if sz <= 0:
            notes.append("Slices share one position; slice spacing taken as 1.")
            sz = 1.0
        elif np.max(np.abs(gaps - sz)) > 0.01 * sz + 1e-6:
            notes.append(
                f"Slice spacing varies ({gaps.min():g} to {gaps.max():g}); using the median {sz:g}."
            )
    else:
        sz = float(ds0.get("SpacingBetweenSlices", ds0.get("SliceThickness", 1.0)) or 1.0)
    return (sx, sy, sz)
