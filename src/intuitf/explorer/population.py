"""Fresh transfer functions: uniform random ones and ones placed on the volume's materials."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from intuitf.explorer.bounds import Bounds
from intuitf.tf.defaults import Material, find_materials
from intuitf.tf.gaussian import Gaussian, GaussianTF

#: Draws a Gaussian's colour: ``color(rng) -> (r, g, b)``.
ColorSampler = Callable[[np.random.Generator], tuple[float, float, float]]


def _clip(v: float, r: tuple[float, float]) -> float:
    return min(r[1], max(r[0], float(v)))


def _height(rng: np.random.Generator, bounds: Bounds, sampling: str) -> float:
    if sampling == "uniform":
        return float(rng.uniform(*bounds.height))
    return bounds.sample_height(rng)


def _width(rng: np.random.Generator, bounds: Bounds, sampling: str) -> float:
    if sampling == "uniform":
        return float(rng.uniform(*bounds.width))
    return bounds.sample_width(rng)


def random_tf(
    rng: np.random.Generator,
    n_gaussians: int,
    bounds: Bounds,
    *,
    sampling: str = "log",
    value_range: tuple[float, float] | None = None,
    color: ColorSampler | None = None,
) -> GaussianTF:
    """``n_gaussians`` Gaussians drawn within ``bounds``, sorted by mean.

    Means and colours (in HSL) are uniform; widths and heights log-uniform (``sampling``
    "log") or uniform within the hard bounds ("uniform", the authors' way). ``color``
    replaces the colour draw (for instance to draw from the intent's palette).
    """
    color = color or bounds.sample_color
    gs = []
    for _ in range(n_gaussians):
        mean = float(rng.uniform(*bounds.mean))
        width = _width(rng, bounds, sampling)
        height = _height(rng, bounds, sampling)
        gs.append(Gaussian(mean, width, height, color(rng)))
    return GaussianTF(tuple(sorted(gs, key=lambda g: g.mean)), value_range=value_range)


def materials_of(histogram: np.ndarray | None, n_gaussians: int) -> list[Material]:
    """The volume's materials (histogram peaks and tail quantiles), or none without a histogram."""
    if histogram is None:
        return []
    counts = np.asarray(histogram, dtype=np.float64).ravel()
    if counts.size < 8 or counts.sum() <= 0:
        return []
    return find_materials(counts, max_materials=max(1, n_gaussians))


def seeded_tf(
    rng: np.random.Generator,
    materials: Sequence[Material],
    n_gaussians: int,
    bounds: Bounds,
    *,
    value_range: tuple[float, float] | None = None,
    color: ColorSampler | None = None,
) -> GaussianTF:
    """A TF whose Gaussians sit on the volume's materials, so its rendering shows them.

    One Gaussian per material (a random subset when there are more materials than
    Gaussians), centred near the material's value with about its spread. Gaussians left over
    go to the ranges between neighbouring materials (where boundaries between materials, such
    as a surface, live) and then anywhere. Heights and colours are random: which material is
    opaque and in which colour is for the search to find (``color`` as in :func:`random_tf`).
    """
    color = color or bounds.sample_color
    mats = list(materials)
    if len(mats) > n_gaussians:
        pick = sorted(int(i) for i in rng.choice(len(mats), size=n_gaussians, replace=False))
        mats = [mats[i] for i in pick]
    gs: list[Gaussian] = []
    for m in mats:
        mean = _clip(m.center + rng.normal(0.0, 0.25 * m.spread), bounds.mean)
        width = _clip(max(m.spread, bounds.width[0]) * math.exp(rng.normal(0.0, 0.4)), bounds.width)
        gs.append(Gaussian(mean, width, bounds.sample_height(rng), color(rng)))
    gaps = [(a.center + b.center) / 2.0 for a, b in zip(mats[:-1], mats[1:], strict=False)]
    order: Any = rng.permutation(len(gaps)) if gaps else []
    for k in order:
        if len(gs) >= n_gaussians:
            break
        a, b = mats[int(k)], mats[int(k) + 1]
        mean = _clip(gaps[int(k)] + rng.normal(0.0, 0.1 * (b.center - a.center)), bounds.mean)
        gs.append(Gaussian(mean, bounds.sample_width(rng), bounds.sample_height(rng), color(rng)))
    while len(gs) < n_gaussians:
        gs.append(
            Gaussian(
                float(rng.uniform(*bounds.mean)),
                bounds.sample_width(rng),
                bounds.sample_height(rng),
                color(rng),
            )
        )
    return GaussianTF(tuple(sorted(gs, key=lambda g: g.mean)), value_range=value_range)
