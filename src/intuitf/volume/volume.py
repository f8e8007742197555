"""The :class:`Volume`: a scalar field normalised to [0, 1] that remembers its own units."""

from __future__ import annotations

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
        value. An empty or constant array raises :class:`VolumeError`.
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
        notes: list[str] = []
        work = a.astype(np.float64 if a.dtype.itemsize > 4 else np.float32, copy=False)
        if a.dtype.kind == "f":
            finite = np.isfinite(work)
            n_bad = int(work.size - np.count_nonzero(finite))
            if n_bad == work.size:
                raise VolumeError(f"{name}: every voxel is NaN or Inf; there is nothing to render.")
            if n_bad:
                fill = float(work[finite].min())
                work = np.where(finite, work, fill)
                notes.append(
                    f"{n_bad} NaN/Inf voxel(s) ({100.0 * n_bad / work.size:.3g}%) "
                    f"replaced by the minimum finite value {fill:g}."
                )
        if value_range is None:
            lo, hi = float(work.min()), float(work.max())
        else:
            lo, hi = (float(v) for v in value_range)
        if not hi > lo:
            raise VolumeError(
                f"{name}: the volume is constant (every voxel is {lo:g}); a transfer function "
                "cannot show any structure in it.",
                "Check that the right file, dtype and byte order were used.",
            )
        data = ((work - lo) / (hi - lo)).astype(np.float32)
        np.clip(data, 0.0, 1.0, out=data)
        return cls(
            data=np.ascontiguousarray(data),
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
