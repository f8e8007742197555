"""NumPy ``.npy`` and ``.npz`` files.

Arrays are taken as ``[z, y, x]`` already (the layout a :class:`~intuitf.volume.Volume`
stores). An ``.npz`` may hold the volume under ``data``, ``volume`` or as its only array, and an
optional ``spacing`` array of three numbers (x, y, z). ``.npy`` files are memory-mapped.
"""

from __future__ import annotations

import zipfile

import numpy as np

from intuitf.errors import VolumeError
from intuitf.volume.request import RawArray, ReadRequest


def read(request: ReadRequest) -> RawArray:
    """Read an ``.npy`` or ``.npz`` file."""
    path = request.path
    if path.name.lower().endswith(".npy"):
        try:
            arr = np.load(path, mmap_mode="r", allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise VolumeError(
                f"{path}: not a readable .npy file ({exc}).", "Check that it is complete."
            ) from None
        request.reserve(arr.shape[::-1], arr.dtype, mapped=True)
        return RawArray(arr)
    try:
        with np.load(path, allow_pickle=False) as z:
            keys = list(z.files)
            arrays = [k for k in keys if k != "spacing"]
            if not arrays:
                what = "only a 'spacing' array" if keys else "no arrays at all"
                raise VolumeError(
                    f"{path}: the .npz holds {what}; there is no volume in it.",
                    "Save the volume as np.savez(path, data=volume, spacing=(sx, sy, sz)).",
                )
            key = next((k for k in ("data", "volume") if k in keys), None)
            if key is None and len(arrays) == 1:
                key = arrays[0]
            if key is None:
                raise VolumeError(
                    f"{path}: the .npz holds several arrays ({', '.join(keys)}) and none is "
                    "named 'data' or 'volume'.",
                    "Save the volume as np.savez(path, data=volume, spacing=(sx, sy, sz)).",
                )
            arr = z[key]
            spacing = None
            if "spacing" in keys:
                sp = np.asarray(z["spacing"], dtype=float).ravel()
                if sp.size == 3:
                    spacing = tuple(float(s) for s in sp)
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise VolumeError(
            f"{path}: not a readable .npz file ({exc}).", "Check that it is complete."
        ) from None
    return RawArray(arr, spacing=spacing)  # type: ignore[arg-type]
