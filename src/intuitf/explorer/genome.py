"""Array views of a TF's Gaussians: a normalised vector encoding and near-duplicate tests."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from intuitf.explorer.bounds import Bounds, hsl_to_rgb, rgb_to_hsl
from intuitf.tf.gaussian import Gaussian, GaussianTF

#: Values per Gaussian in the vector encoding: mean, width, height, hue, saturation, lightness.
GENES_PER_GAUSSIAN = 6


def _unit(v: float, lo: float, hi: float) -> float:
    return 0.5 if hi <= lo else min(1.0, max(0.0, (v - lo) / (hi - lo)))


def _from_unit(u: float, lo: float, hi: float) -> float:
    return lo + min(1.0, max(0.0, float(u))) * (hi - lo)


def encode(tf: GaussianTF, bounds: Bounds | None = None) -> np.ndarray:
    """The free (unfrozen) Gaussians of ``tf`` as a vector in [0, 1]^(6·n_free).

    Per Gaussian: mean, log width, log height, hue, saturation, lightness, each mapped
    linearly from its bound to [0, 1] (values outside the bounds are clipped). Widths and
    heights are encoded in log space, where equal steps are equal relative changes; that is
    how opacity and feature size are perceived.
    """
    b = bounds or Bounds()
    lw = (math.log(b.width[0]), math.log(b.width[1]))
    lh = (math.log(b.height_floor), math.log(max(b.height[1], b.height_floor * 1.0001)))
    out: list[float] = []
    for g in tf.gaussians:
        if g.frozen:
            continue
        h, s, lum = rgb_to_hsl(g.color)
        out += [
            _unit(g.mean, *b.mean),
            _unit(math.log(g.width), *lw),
            _unit(math.log(max(g.height, b.height_floor)), *lh),
            _unit(h, *b.hue),
            _unit(s, *b.saturation),
            _unit(lum, *b.lightness),
        ]
    return np.asarray(out, dtype=np.float64)


def decode(x: np.ndarray, template: GaussianTF, bounds: Bounds | None = None) -> GaussianTF:
    """The TF that ``x`` (from :func:`encode`) stands for; frozen Gaussians come from ``template``.

    Values are clipped to [0, 1] first, so every decoded TF lies inside ``bounds``.
    """
    b = bounds or Bounds()
    x = np.asarray(x, dtype=np.float64).ravel()
    n_free = int((~template.frozen_mask()).sum())
    if x.size != GENES_PER_GAUSSIAN * n_free:
        raise ValueError(f"decode expects {GENES_PER_GAUSSIAN * n_free} values, got {x.size}.")
    lw = (math.log(b.width[0]), math.log(b.width[1]))
    lh = (math.log(b.height_floor), math.log(max(b.height[1], b.height_floor * 1.0001)))
    gs: list[Gaussian] = []
    k = 0
    for g in template.gaussians:
        if g.frozen:
            gs.append(g)
            continue
        v = x[k : k + GENES_PER_GAUSSIAN]
        k += GENES_PER_GAUSSIAN
        height = min(b.height[1], max(b.height[0], math.exp(_from_unit(v[2], *lh))))
        color = b.clip_color(
            hsl_to_rgb(
                _from_unit(v[3], *b.hue),
                _from_unit(v[4], *b.saturation),
                _from_unit(v[5], *b.lightness),
            )
        )
        gs.append(
            replace(
                g,
                mean=_from_unit(v[0], *b.mean),
                width=min(b.width[1], max(b.width[0], math.exp(_from_unit(v[1], *lw)))),
                height=height,
                color=color,
            )
        )
    return template.with_gaussians(gs)


def params(tf: GaussianTF) -> np.ndarray:
    """Raw parameters, shape (N, 6): mean, width, height, r, g, b, rows sorted by mean."""
    rows = sorted((g.mean, g.width, g.height, *g.color) for g in tf.gaussians)
    return np.asarray(rows, dtype=np.float64)


#: A Gaussian this low (opacity per voxel) shows nowhere: its other attributes do not matter.
HIDDEN_HEIGHT = 1e-4


def near_duplicate(a: GaussianTF, b: GaussianTF, tol: float = 2e-3) -> bool:
    """Whether ``a`` and ``b`` have the same visible Gaussians up to order and ``tol``.

    Gaussians of height at most :data:`HIDDEN_HEIGHT` are left out (a hidden feature's
    position or colour does not change the picture, so two TFs that differ only there would
    be rendered and judged twice for nothing). Means, widths and colour channels must agree
    within ``tol``; heights within ``tol`` relative to the larger of the two (a 0.2 % change
    in opacity does not show), or 1e-4.
    """
    pa, pb = params(a), params(b)
    pa, pb = pa[pa[:, 2] > HIDDEN_HEIGHT], pb[pb[:, 2] > HIDDEN_HEIGHT]
    if len(pa) != len(pb):
        return False
    d = np.abs(pa - pb)
    h_tol = np.maximum(tol * np.maximum(pa[:, 2], pb[:, 2]), 1e-4)
    return bool((d[:, [0, 1, 3, 4, 5]] <= tol).all() and (d[:, 2] <= h_tol).all())


def is_duplicate_of_any(tf: GaussianTF, others: Sequence[GaussianTF], tol: float = 2e-3) -> bool:
    return any(near_duplicate(tf, o, tol) for o in others)
