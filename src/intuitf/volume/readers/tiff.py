"""Multi-page TIFF files and folders of single-page TIFF slices, through tifffile.

Pages (or slice files, in natural name order: ``s2.tif`` before ``s10.tif``) are z; each page's
rows are y and columns x. Spacing comes from the resolution tags (pixels per unit) and, for
ImageJ stacks, the ``spacing`` entry of the ImageJ metadata; otherwise it is left unknown.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import tifffile

from intuitf.errors import VolumeError
from intuitf.volume.request import RawArray, ReadRequest


def _natural_key(p: Path) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", p.name)]


def _xy_spacing(page: tifffile.TiffPage) -> tuple[float, float] | None:
    try:
        xr = page.tags["XResolution"].value
        yr = page.tags["YResolution"].value
    except KeyError:
        return None
    sx = xr[1] / xr[0] if xr[0] else 0.0
    sy = yr[1] / yr[0] if yr[0] else 0.0
    if sx > 0 and sy > 0 and not (sx == 1.0 and sy == 1.0):
        return (float(sx), float(sy))
    return None


def read(request: ReadRequest) -> RawArray:
    """Read a multi-page TIFF, or a folder of TIFF slices."""
    path = request.path
    notes: list[str] = []
    try:
        if path.is_dir():
            files = sorted(
                (p for p in path.iterdir() if p.name.lower().endswith((".tif", ".tiff"))),
                key=_natural_key,
            )
            if len(files) < 2:
                raise VolumeError(
                    f"{path}: a folder of TIFF slices needs at least two .tif files.",
                    "Point at the folder holding every slice.",
                )
            with tifffile.TiffFile(files[0]) as tf:
                page = tf.pages[0]
                shape2 = page.shape
                dtype = page.dtype
                xy = _xy_spacing(page)
                ij = tf.imagej_metadata or {}
            if len(shape2) != 2:
                raise VolumeError(
                    f"{files[0]}: each slice must be a single-channel 2D image, got shape "
                    f"{shape2}.",
                    "Save grey-scale slices.",
                )
            request.reserve((shape2[1], shape2[0], len(files)), dtype)
            arr = np.stack([_read_slice(f, shape2) for f in files])
        else:
            with tifffile.TiffFile(path) as tf:
                series = tf.series[0]
                shape = tuple(int(s) for s in series.shape)
                page = tf.pages[0]
                xy = _xy_spacing(page)
                ij = tf.imagej_metadata or {}
                squeezed = tuple(s for s in shape if s != 1)
                if len(squeezed) != 3:
                    raise VolumeError(
                        f"{path}: expected a stack of single-channel pages (3D), got shape "
                        f"{shape}.",
                        "Save the volume as a multi-page grey-scale TIFF.",
                    )
                request.reserve((squeezed[2], squeezed[1], squeezed[0]), series.dtype)
                arr = series.asarray().reshape(squeezed)
    except (tifffile.TiffFileError, ValueError, OSError, IndexError, KeyError) as exc:
        raise VolumeError(
            f"{path}: not a readable TIFF ({exc}).", "Check that the file is complete."
        ) from None
    sz = ij.get("spacing")
    spacing = None
    if xy is not None or sz:
        sx, sy = xy or (1.0, 1.0)
        spacing = (sx, sy, float(sz) if sz else 1.0)
    return RawArray(arr, spacing=spacing, notes=notes)


def _read_slice(f: Path, shape2: tuple[int, ...]) -> np.ndarray:
    img = tifffile.imread(f)
    if img.shape != shape2:
        raise VolumeError(
            f"{f}: this slice is {img.shape}, the first one is {shape2}.",
            "Every slice in the folder must have the same size.",
        )
    return img
