"""DiffDVR ``.cvol`` volumes (uncompressed).

Layout, all little-endian: a 64-byte header (magic ``cvol``; sizes X, Y, Z as int64; voxel
sizes x, y, z as float64; a type code as int32, 0 = uint8, 1 = uint16, 2 = float32; a
compression flag byte; padding), then the voxels with x varying fastest, then y, then z.
LZ4-chunked files (compression flag 1) are refused with advice on converting them.
"""

from __future__ import annotations

import struct

import numpy as np

from intuitf.errors import VolumeError
from intuitf.volume.request import RawArray, ReadRequest

HEADER_BYTES = 64
_TYPES = {0: np.dtype("<u1"), 1: np.dtype("<u2"), 2: np.dtype("<f4")}


def read(request: ReadRequest) -> RawArray:
    """Read an uncompressed ``.cvol`` file (memory-mapped)."""
    path = request.path
    with open(path, "rb") as fh:
        head = fh.read(HEADER_BYTES)
    if len(head) < HEADER_BYTES or head[:4] != b"cvol":
        raise VolumeError(
            f"{path}: not a .cvol file (no 'cvol' magic in a 64-byte header).",
            "Check that the file is a DiffDVR volume and complete.",
        )
    x, y, z = struct.unpack_from("<3q", head, 4)
    spacing = struct.unpack_from("<3d", head, 28)
    (code,) = struct.unpack_from("<i", head, 52)
    compressed = head[56]
    if compressed:
        raise VolumeError(
            f"{path}: this .cvol is LZ4-chunked (compression flag {compressed}); compressed "
            ".cvol files are not supported.",
            "Re-save it uncompressed with DiffDVR (pyrenderer: Volume(path).save(out, "
            "compression=0)), or export it as .raw/.nrrd and load that.",
        )
    if code not in _TYPES:
        raise VolumeError(
            f"{path}: unknown .cvol voxel type code {code} (expected 0 = uint8, 1 = uint16, "
            "2 = float32).",
            "Check that the file is complete and not corrupt.",
        )
    if min(x, y, z) < 1:
        raise VolumeError(f"{path}: invalid .cvol grid size {x}x{y}x{z}.", "The header is corrupt.")
    dtype = _TYPES[code]
    expected = HEADER_BYTES + x * y * z * dtype.itemsize
    actual = path.stat().st_size
    if actual < expected:
        raise VolumeError(
            f"{path}: a {x}x{y}x{z} {dtype.name} .cvol needs {expected} bytes, but the file has "
            f"{actual}; it is truncated.",
            "Copy or download the file again.",
        )
    request.reserve((x, y, z), dtype, mapped=True)
    arr = np.memmap(path, dtype=dtype, mode="r", offset=HEADER_BYTES, shape=(z, y, x))
    sp = tuple(float(s) for s in spacing)
    ok = all(np.isfinite(s) and s > 0 for s in sp)
    return RawArray(arr, spacing=sp if ok else None)  # type: ignore[arg-type]


def write_cvol(path, array: np.ndarray, spacing=(1.0, 1.0, 1.0)) -> None:
    """Write ``array`` (``[z, y, x]``; uint8, uint16 or float32) as an uncompressed .cvol."""
    codes = {np.dtype("u1"): 0, np.dtype("u2"): 1, np.dtype("f4"): 2}
    a = np.asarray(array)
    key = a.dtype.newbyteorder("=")
    if key not in codes:
        raise VolumeError(f".cvol stores uint8, uint16 or float32, not {a.dtype}.")
    z, y, x = a.shape
    head = b"cvol" + struct.pack("<3q3di", x, y, z, *map(float, spacing), codes[key])
    head += bytes(HEADER_BYTES - len(head))
    with open(path, "wb") as fh:
        fh.write(head)
        fh.write(np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).tobytes())
