"""What a reader is asked for, what it hands back, and the memory check before a big read.

Every reader receives a :class:`ReadRequest` and returns a :class:`RawArray`: the voxels in the
file's own dtype, indexed ``[z, y, x]`` (x varies fastest in memory), with the spacing along
(x, y, z). Readers call :meth:`ReadRequest.reserve` as soon as they know the grid size, *before*
reading the voxels, so that a volume too large for this machine fails fast with advice instead of
being killed by the operating system halfway through.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from intuitf.errors import VolumeError

#: Bytes per voxel the normalisation in ``Volume.from_array`` needs besides the source array
#: (a float working copy, the normalised result and a temporary of the same size).
_WORK_BYTES_PER_VOXEL = 12

#: Fraction of the available memory a load may plan to use; the rest is headroom for the
#: renderer, which needs memory of its own once the volume is loaded.
_MEMORY_FRACTION = 0.8


def available_memory_bytes() -> int:
    """Memory this process can still use, from ``MemAvailable`` in /proc/meminfo.

    Falls back to free physical pages from ``os.sysconf`` where /proc is missing.
    """
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 1 << 62  # unknown: do not block the load


def _fmt_bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover


def output_dims(dims_xyz: tuple[int, int, int], max_dim: int | None) -> tuple[int, int, int]:
    """Grid size after shrinking so that no axis exceeds ``max_dim`` (aspect ratio kept)."""
    if max_dim is None or max(dims_xyz) <= max_dim:
        return tuple(int(d) for d in dims_xyz)  # type: ignore[return-value]
    f = max(dims_xyz) / max_dim
    return tuple(max(2, min(max_dim, round(d / f))) if d > 1 else 1 for d in dims_xyz)  # type: ignore[return-value]


@dataclass
class ReadRequest:
    """A request to read one volume file, with the user's overrides.

    ``shape`` is (X, Y, Z) and ``spacing`` is (x, y, z); ``dtype`` and ``byte_order`` are only
    used by headerless formats (raw). ``max_dim`` asks for downsampling after reading.
    """

    path: Path
    shape: tuple[int, int, int] | None = None
    dtype: str | None = None
    byte_order: str | None = None
    spacing: tuple[float, float, float] | None = None
    max_dim: int | None = None

    def reserve(
        self, dims_xyz: tuple[int, int, int], dtype: np.dtype | str, *, mapped: bool = False
    ) -> None:
        """Raise :class:`VolumeError` unless a volume of this size fits in memory.

        ``mapped`` says the reader can memory-map the voxels, so that with ``max_dim`` only the
        downsampled result needs to fit.
        """
        dt = np.dtype(dtype)
        n = int(np.prod([int(d) for d in dims_xyz], dtype=np.int64))
        out = output_dims(dims_xyz, self.max_dim)
        m = int(np.prod(out, dtype=np.int64))
        work = _WORK_BYTES_PER_VOXEL if dt.itemsize <= 4 else 3 * 8 + 4
        if m < n:  # downsampled: the source (unless mapped) plus the small result
            need = (0 if mapped else n * dt.itemsize) + m * (4 + work)
        else:
            need = n * (dt.itemsize + work)
        avail = available_memory_bytes()
        if need <= _MEMORY_FRACTION * avail:
            return
        dims = "x".join(str(d) for d in dims_xyz)
        # The largest max_dim whose result would fit (the result scales with max_dim ** 3).
        fit = int(max(dims_xyz) * ((_MEMORY_FRACTION * avail) / max(need, 1)) ** (1 / 3))
        hint = (
            f"Pass --max-dim {max(16, fit)} (or max_dim={max(16, fit)}) to downsample while "
            "loading, or use a machine with more memory."
        )
        if m < n and not mapped:
            hint = (
                "Even downsampled, this format must be read whole. Convert it to an "
                "uncompressed .raw or .npy file (which can be read in slabs) and pass "
                "--max-dim, or use a machine with more memory."
            )
        raise VolumeError(
            f"{self.path}: a {dims} {dt.name} volume needs about {_fmt_bytes(need)} of memory "
            f"to load, but only {_fmt_bytes(avail)} is available.",
            hint,
        )


@dataclass
class RawArray:
    """A reader's result: voxels in the file's dtype, ``[z, y, x]``, and what it learned.

    ``array`` may be a read-only memory map. ``spacing`` is (x, y, z) or None when the file
    does not say. ``notes`` are facts worth telling the user (slices skipped, axes dropped).
    """

    array: np.ndarray
    spacing: tuple[float, float, float] | None = None
    notes: list[str] = field(default_factory=list)
    name: str | None = None
