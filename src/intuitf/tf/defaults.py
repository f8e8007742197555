"""Histogram-aware starting points: where a volume's materials are, and a first TF that shows them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from intuitf.tf.gaussian import WIDTH_RANGE, Gaussian, GaussianTF


@dataclass(frozen=True)
class Material:
    """A range of values that many voxels share: a peak of the histogram or a plateau of it."""

    center: float  # normalised value
    spread: float  # standard deviation of the values around it (normalised)
    fraction: float  # share of foreground voxels near it


def background_cutoff(counts: np.ndarray) -> float:
    """Normalised value below which voxels are background (air, empty space).

    The first valley after a dominant low-value mode (air around a CT scan), or after a mode
    in the lower half that holds at least 30 % of the voxels (a scan whose surrounding medium
    is not at the bottom of the range, like the embedding around a tooth); 0 when neither.
    """
    c = counts.astype(np.float64)
    n = c.size
    from scipy.ndimage import gaussian_filter1d
    from scipy.signal import find_peaks

    logc = gaussian_filter1d(np.log1p(c), 2.0)
    if c[: max(1, n // 10)].sum() >= 0.2 * c.sum():
        first = int(np.argmax(logc[: max(2, n // 4)]))
    else:
        first = int(np.argmax(c[: max(2, n // 2)]))
        half = max(1, n // 64)
        if c[max(0, first - half) : first + half + 1].sum() < 0.3 * c.sum():
            return 0.0
    valleys, _ = find_peaks(-logc[first:])
    idx = first + int(valleys[0]) if len(valleys) else first + max(1, n // 50)
    return float(min(idx, first + n // 3)) / (n - 1)


def find_materials(counts: np.ndarray, max_materials: int = 5) -> list[Material]:
    """Locate the volume's materials from its histogram (``counts`` over [0, 1]).

    Peaks of the smoothed log histogram above the background are materials; if the
    histogram is a long tail without peaks, quantiles of the foreground stand in for them.
    Sorted by value.
    """
    c = np.asarray(counts, dtype=np.float64)
    n = c.size
    centers = (np.arange(n) + 0.5) / n
    cut = background_cutoff(c)
    fg = c.copy()
    fg[centers <= cut] = 0.0
    total = fg.sum()
    if total <= 0:
        fg = c.copy()
        total = fg.sum()
    from scipy.ndimage import gaussian_filter1d
    from scipy.signal import find_peaks

    logc = gaussian_filter1d(np.log1p(fg), max(1.0, n / 128))
    peaks, props = find_peaks(logc, prominence=0.3)
    mats: list[Material] = []
    order: Any = np.argsort(props["prominences"])[::-1] if len(peaks) else []
    for k in order[:max_materials]:
        p = peaks[k]
        lo, hi = max(0, p - n // 32), min(n, p + n // 32 + 1)
        w = fg[lo:hi]
        frac = float(w.sum() / total)
        mu = float((centers[lo:hi] * w).sum() / max(w.sum(), 1e-12))
        var = float(((centers[lo:hi] - mu) ** 2 * w).sum() / max(w.sum(), 1e-12))
        mats.append(Material(center=mu, spread=max(np.sqrt(var), 1.0 / n), fraction=frac))
    # A long tail (bone in CT) rarely makes a peak: add upper quantiles of the foreground.
    cdf = np.cumsum(fg) / total
    for q in (0.5, 0.9, 0.99):
        if len(mats) >= max_materials:
            break
        v = float(centers[min(n - 1, int(np.searchsorted(cdf, q)))])
        if all(abs(v - m.center) > 0.06 for m in mats):
            mats.append(Material(center=v, spread=0.02, fraction=0.0))
    return sorted(mats, key=lambda m: m.center)


#: Colours for successive materials, from low to high values: skin-like, red, orange, ivory, white.
_RAMP = [
    (0.85, 0.55, 0.45),
    (0.80, 0.25, 0.20),
    (0.90, 0.60, 0.25),
    (0.95, 0.90, 0.75),
    (1.00, 1.00, 1.00),
]


def default_tf(counts: np.ndarray, value_range: tuple[float, float] | None = None) -> GaussianTF:
    """A first TF that shows a volume's structures: faint low materials, opaque high ones.

    ``counts`` is the histogram over [0, 1] (``Volume.histogram()[0]``).
    """
    mats = find_materials(counts, max_materials=4)
    if not mats:
        mats = [Material(0.5, 0.05, 1.0)]
    k = len(mats)
    gaussians = []
    for i, m in enumerate(mats):
        t = i / max(1, k - 1)
        # Low-value materials fill space (skin, tissue): keep them faint so the inside shows.
        height = float(0.02 + (0.6 - 0.02) * t**2)
        width = float(np.clip(max(m.spread, 0.015), WIDTH_RANGE[0], 0.08))
        color = _RAMP[min(len(_RAMP) - 1, round(t * (len(_RAMP) - 2)) + (1 if t == 1 else 0))]
        gaussians.append(
            Gaussian(mean=float(np.clip(m.center, 0, 1)), width=width, height=height, color=color)
        )
    return GaussianTF(tuple(gaussians), value_range=value_range, name="default")
