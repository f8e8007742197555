"""The :class:`Volume`: a scalar field normalised to [0, 1] that remembers its own units."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from intuitf.errors import VolumeError


@dataclass(eq=False)
class Volume:
    """A 3D scalar volume.

    ``data`` is float32, C-contiguous, indexed ``data[z, y, x]`` and normalised to [0, 1]
    with ``value_range`` mapping 0 and 1 back to the data's own units, so that exported
    transfer functions speak those units. ``spacing`` is the voxel size along (x, y, z).
    ``notes`` records what was done to the data while loading (NaN replaced, downsampled, ...).
    """

    data: np.ndarray
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0)
    name: str = "volume"
    original_dtype: str = "float32"
    value_range: tuple[float, float] = (0.0, 1.0)
    source: str | None = None
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.data.ndim != 3:
            raise VolumeError(f"{self.name}: a volume must be 3D, got shape {self.data.shape}.")
        if self.data.dtype != np.float32 or not self.data.flags.c_contiguous:
            self.data = np.ascontiguousarray(self.data, dtype=np.float32)
        sp = tuple(float(s) for s in self.spacing)
        if len(sp) != 3 or not all(np.isfinite(s) and s > 0 for s in sp):
            raise VolumeError(
                f"{self.name}: spacing must be three positive numbers, got {self.spacing}.",
                "Pass --spacing X,Y,Z with positive values.",
            )
        self.spacing = sp  # type: ignore[assignment]
        lo, hi = (float(v) for v in self.value_range)
        self.value_range = (lo, hi)

    @classmethod
    def from_array(
        cls,
        array: np.ndarray,
        *,
        spacing: tuple[float, float, float] = (1.0, 1.0, 1.0),
        name: str = "volume",
        source: str | None = None,
        value_range: tuple[float, float] | None = None,
    ) -> Volume:
        """Normalise ``array`` (indexed [z, y, x]) to [0, 1] and wrap it.

        NaN and Inf values are reported in ``notes`` and replaced by the smallest finite
        value; so are values too extreme to share one value range with the rest (see
        :func:`scan_values`). Arithmetic is done in float64, slab by slab. An empty or constant
        array raises :class:`VolumeError`.
        ``value_range`` fixes the original range (for example the full range of a dtype);
        by default the data's finite min and max are used.
        """
        a = np.asarray(array)
        if a.ndim != 3:
            raise VolumeError(
                f"{name}: expected a 3D array, got shape {a.shape}.",
                "Check the file's dimensions, or pass --shape X,Y,Z for raw files.",
            )
        if a.size == 0 or min(a.shape) == 0:
            raise VolumeError(f"{name}: the volume is empty (shape {a.shape}).")
        if a.dtype.kind not in "uifb":
            raise VolumeError(f"{name}: unsupported voxel type {a.dtype}.")
        original_dtype = a.dtype.name
        scan = scan_values(a, name)
        notes = scan.notes()
        if value_range is None:
            lo, hi = scan.lo, scan.hi
        else:
            lo, hi = (float(v) for v in value_range)
        if not hi > lo:
            raise VolumeError(
                f"{name}: the volume is constant (every voxel is {lo:g}); a transfer function "
                "cannot show any structure in it.",
                "Check that the right file, dtype and byte order were used.",
            )
        if not math.isfinite(hi - lo):
            raise VolumeError(
                f"{name}: the value range {lo:g} .. {hi:g} is wider than a 64-bit number holds.",
                f"Give a value range within ±{EXTREME:.3g}.",
            )
        data = normalise(a, lo, hi, fill=scan.fill, limit=scan.limit)
        return cls(
            data=data,
            spacing=spacing,
            name=name,
            original_dtype=original_dtype,
            value_range=(lo, hi),
            source=source,
            notes=notes,
        )

    # -- geometry -------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int]:
        """Array shape, (z, y, x)."""
        return tuple(self.data.shape)  # type: ignore[return-value]

    @property
    def dims(self) -> tuple[int, int, int]:
        """Grid size along (x, y, z)."""
        z, y, x = self.data.shape
        return (x, y, z)

    @property
    def extent(self) -> tuple[float, float, float]:
        """Physical size of the box through the voxel centres, along (x, y, z)."""
        return tuple((n - 1) * s for n, s in zip(self.dims, self.spacing, strict=True))  # type: ignore[return-value]

    # -- values ---------------------------------------------------------------------------
    @property
    def lut_size(self) -> int:
        """Number of lookup-table entries that resolves this volume's values.

        256 for 8-bit data; for wider data one entry per original integer value, up to 4096.
        """
        if self.original_dtype in ("uint8", "int8", "bool"):
            return 256
        lo, hi = self.value_range
        if np.dtype(self.original_dtype).kind in "ui":
            return int(min(4096, max(256, hi - lo + 1)))
        return 4096

    def to_original(self, normalised: np.ndarray | float) -> np.ndarray | float:
        """Map normalised values in [0, 1] to the data's own units."""
        lo, hi = self.value_range
        return (
            lo + np.asarray(normalised) * (hi - lo)
            if np.ndim(normalised)
            else lo + float(normalised) * (hi - lo)
        )

    def to_normalised(self, original: np.ndarray | float) -> np.ndarray | float:
        """Map values in the data's own units to [0, 1]."""
        lo, hi = self.value_range
        return (
            (np.asarray(original) - lo) / (hi - lo)
            if np.ndim(original)
            else (float(original) - lo) / (hi - lo)
        )

    def histogram(self, bins: int = 256) -> tuple[np.ndarray, np.ndarray]:
        """Counts and bin edges of the normalised values over [0, 1]."""
        counts, edges = np.histogram(self.data, bins=bins, range=(0.0, 1.0))
        return counts, edges

    def summary(self) -> dict:
        """Facts about the volume for ``intuitf info`` and run records."""
        d = self.data
        lo, hi = self.value_range
        return {
            "name": self.name,
            "source": self.source,
            "dims_xyz": list(self.dims),
            "dtype": self.original_dtype,
            "value_range": [lo, hi],
            "mean": float(self.to_original(float(d.mean()))),
            "spacing_xyz": list(self.spacing),
            "notes": list(self.notes),
        }


# -- value ranges --------------------------------------------------------------------------
#: Largest magnitude a value may have when values of both signs occur so that ``hi - lo``
#: (the width of the value range) still fits in a 64-bit float.
EXTREME = float(np.finfo(np.float64).max) / 2

_SLAB = 32  # z-slices per pass: bounded memory, memory maps read once


@dataclass
class ValueScan:
    """What :func:`scan_values` found: the usable range and the voxels left out of it.

    ``nonfinite`` voxels are NaN or Inf; ``extreme`` voxels are finite but beyond ``limit``
    (:data:`EXTREME`). Both are replaced by ``fill`` (the smallest usable value) when
    normalising.
    """

    lo: float
    hi: float
    size: int
    nonfinite: int = 0
    extreme: int = 0
    limit: float | None = None
    full_range: tuple[float, float] | None = None

    @property
    def fill(self) -> float | None:
        return self.lo if (self.nonfinite or self.extreme) else None

    def notes(self) -> list[str]:
        out = []
        if self.nonfinite:
            out.append(
                f"{self.nonfinite} NaN/Inf voxel(s) ({100.0 * self.nonfinite / self.size:.3g}%) "
                f"replaced by the minimum finite value {self.lo:g}."
            )
        if self.extreme:
            flo, fhi = self.full_range or (self.lo, self.hi)
            out.append(
                f"{self.extreme} voxel(s) ({100.0 * self.extreme / self.size:.3g}%) with values "
                f"beyond ±{self.limit:.3g} (the data spans {flo:g} .. {fhi:g}) replaced by the "
                f"minimum remaining value {self.lo:g}: such values are usually markers for "
                "'no data', and they would leave every other value in one grey level."
            )
        return out


def _slab_min_max(a: np.ndarray) -> tuple[float, float, float, float, int, int]:
    """Finite min and max; min and max of the values within ±EXTREME; the counts of NaN/Inf
    and of finite values beyond ±EXTREME. Slab by slab, so memory maps are read once."""
    lo, hi, lo_all, hi_all = math.inf, -math.inf, math.inf, -math.inf
    nonfinite = extreme = 0
    for z0 in range(0, a.shape[0], _SLAB):
        s = np.asarray(a[z0 : z0 + _SLAB])
        if s.dtype.kind == "f":
            n = s.size
            s = s[np.isfinite(s)]
            nonfinite += n - s.size
            if s.size:
                lo_all, hi_all = min(lo_all, float(s.min())), max(hi_all, float(s.max()))
            if s.size and (lo_all < -EXTREME or hi_all > EXTREME):
                small = np.abs(s) <= EXTREME
                extreme += int(s.size - np.count_nonzero(small))
                s = s[small]
        if s.size:
            lo, hi = min(lo, float(s.min())), max(hi, float(s.max()))
            if a.dtype.kind != "f":
                lo_all, hi_all = lo, hi
    return lo, hi, lo_all, hi_all, nonfinite, extreme


def scan_values(a: np.ndarray, name: str = "volume") -> ValueScan:
    """The finite minimum and maximum of ``a`` (read slab by slab, memory-map friendly).

    Finite values beyond ±:data:`EXTREME` (half the largest 64-bit float, as in ±1e308) are
    left out and counted as ``extreme``: they are almost always "no data" markers, they would
    squeeze every real value into one grey level, and with both signs ``hi - lo`` overflows.
    Only when nothing else is left and the range is still computable are they kept.
    Raises :class:`VolumeError` when no usable value remains.
    """
    lo, hi, lo_all, hi_all, nonfinite, extreme = _slab_min_max(a)
    if nonfinite == a.size:
        raise VolumeError(f"{name}: every voxel is NaN or Inf; there is nothing to render.")
    if not extreme:
        return ValueScan(lo, hi, int(a.size), nonfinite)
    if lo <= hi:
        return ValueScan(lo, hi, int(a.size), nonfinite, extreme, EXTREME, (lo_all, hi_all))
    if math.isfinite(hi_all - lo_all):
        return ValueScan(lo_all, hi_all, int(a.size), nonfinite)
    raise VolumeError(
        f"{name}: every finite value is beyond ±{EXTREME:.3g} (range {lo_all:g} .. "
        f"{hi_all:g}); the range is too wide to compute with.",
        "Rescale the data to a smaller range before loading it.",
    )


def clean_slab(s: np.ndarray, fill: float | None, limit: float | None) -> np.ndarray:
    """A float64 copy of ``s`` with NaN/Inf (and values beyond ``limit``) set to ``fill``."""
    s = np.array(s, dtype=np.float64)
    if fill is not None:
        bad = ~np.isfinite(s)
        if limit is not None:
            with np.errstate(invalid="ignore"):
                bad |= np.abs(s) > limit
        s[bad] = fill
    return s


def normalise(
    a: np.ndarray,
    lo: float,
    hi: float,
    *,
    fill: float | None = None,
    limit: float | None = None,
) -> np.ndarray:
    """``(a - lo) / (hi - lo)`` clipped to [0, 1] as C-contiguous float32, computed in float64
    slab by slab (float32 arithmetic overflows for data near its limits)."""
    scale = float(hi) - float(lo)
    out = np.empty(a.shape, dtype=np.float32)
    for z0 in range(0, a.shape[0], _SLAB):
        s = clean_slab(a[z0 : z0 + _SLAB], fill, limit)
        s -= lo
        s /= scale
        np.clip(s, 0.0, 1.0, out=s)
        out[z0 : z0 + _SLAB] = s
    return out
