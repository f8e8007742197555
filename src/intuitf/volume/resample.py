"""Downsampling a volume so that no axis exceeds a maximum size.

Each axis is low-pass filtered (a Gaussian whose width follows the reduction factor, as
scikit-image's ``resize(anti_aliasing=True)`` does) and then resampled linearly with the first
and last voxel centres kept in place, so the physical extent is unchanged. The x and y axes are
reduced slab by slab along z, so a memory-mapped source is read once and never held whole.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from intuitf.volume.request import output_dims
from intuitf.volume.volume import clean_slab

_SLAB = 16  # z-slices per slab: small enough to bound memory, large enough to be quick


def _sigma(old: int, new: int) -> float:
    return max(0.0, (old / new - 1.0) / 2.0)


def downsample(
    array: np.ndarray,
    spacing: tuple[float, float, float],
    max_dim: int,
    fill: float | None = None,
    limit: float | None = None,
    value_range: tuple[float, float] | None = None,
) -> tuple[np.ndarray, tuple[float, float, float]]:
    """Shrink ``array`` (``[z, y, x]``) so that its largest axis is ``max_dim``.

    Returns the float32 result and the new spacing (x, y, z). ``fill`` replaces non-finite
    values (NaN/Inf), and values beyond ``limit``, before filtering, so they do not spread.
    With ``value_range`` (lo, hi) each slab is first normalised to [0, 1] in float64, so data
    near the limits of its type neither overflows nor loses precision. Arrays already small
    enough are returned as float32 (normalised when asked) unchanged otherwise.
    """
    z, y, x = array.shape
    nx, ny, nz = output_dims((x, y, z), max_dim)

    def prepared(slab: np.ndarray) -> np.ndarray:
        if value_range is None and fill is None:
            return np.asarray(slab, dtype=np.float32)
        s = clean_slab(slab, fill, limit)
        if value_range is not None:
            lo, hi = value_range
            s = np.clip((s - lo) / (hi - lo), 0.0, 1.0)
        return s.astype(np.float32)

    if (nx, ny, nz) == (x, y, z):
        return prepared(np.asarray(array)), spacing
    zoom_xy = (ny / y, nx / x)
    sig_xy = (_sigma(y, ny), _sigma(x, nx))
    reduced = np.empty((z, ny, nx), dtype=np.float32)
    for z0 in range(0, z, _SLAB):
        slab = prepared(array[z0 : z0 + _SLAB])
        for k in range(slab.shape[0]):
            img = ndimage.gaussian_filter(slab[k], sig_xy, mode="nearest")
            reduced[z0 + k] = ndimage.zoom(img, zoom_xy, order=1, mode="nearest", grid_mode=False)
    if nz != z:
        reduced = ndimage.gaussian_filter1d(reduced, _sigma(z, nz), axis=0, mode="nearest")
        reduced = ndimage.zoom(reduced, (nz / z, 1, 1), order=1, mode="nearest", grid_mode=False)
    # zoom keeps the corner voxel centres, so the extent (n - 1) * spacing is preserved.
    new_spacing = tuple(
        s * (o - 1) / (n - 1) if n > 1 and o > 1 else s * o / n
        for s, o, n in zip(spacing, (x, y, z), (nx, ny, nz), strict=True)
    )
    return np.ascontiguousarray(reduced), new_spacing  # type: ignore[return-value]
