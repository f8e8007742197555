"""Variation and selection operators on Gaussian-mixture TFs.

Pure functions: each takes the TFs and an ``np.random.Generator`` and returns new TFs.
Frozen Gaussians are never read for swapping nor changed; every changed value is clipped
to the :class:`~intuitf.explorer.bounds.Bounds`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import linear_sum_assignment

from intuitf.explorer.bounds import Bounds, hsl_to_rgb, rgb_to_hsl
from intuitf.explorer.hints import (
    Hint,
    edit_hint,
    edit_step,
    hint_color,
    hint_for,
    sample_hint_height,
)
from intuitf.tf.gaussian import Gaussian, GaussianTF

#: Gaussian attributes crossover may exchange.
ATTRIBUTES = ("mean", "width", "height", "color")

#: Attribute groups exchanged together, after the paper: colour, position, shape.
PAPER_GROUPS: tuple[tuple[str, ...], ...] = (("color",), ("mean",), ("width", "height"))


def _clip(v: float, r: tuple[float, float]) -> float:
    return min(r[1], max(r[0], float(v)))


@dataclass(frozen=True)
class MutationParams:
    """Concrete mutation rates and step sizes (at one point of a stage's progress).

    Steps are standard deviations. With ``additive`` false (the default), width and height
    take multiplicative steps ``x · exp(N(0, step))``: opacity and feature size are perceived
    in ratios, and an additive step that is right for 0.3 wipes out a 0.01 Gaussian. With
    ``additive`` true, every step is additive and scaled by the bound's span, as in the
    authors' prototype. The mean step is in normalised units (fraction of the data range);
    the hue step is in hue units (one turn = 1) and wraps around when the hue bound is full.
    """

    rate: float  # probability that a free Gaussian's width, and its height, change
    mean_rate: float  # probability that a free Gaussian's mean changes
    mean_step: float
    width_step: float
    height_step: float
    color_rate: float  # probability that each of hue, saturation, lightness changes
    hue_step: float
    sl_step: float  # saturation and lightness step, as a fraction of their bound's span
    swap_prob: float = 0.3  # per individual: swap two Gaussians' colours instead of HSL steps
    channel_prob: float = 0.05  # per Gaussian: permute its own RGB channels instead
    additive: bool = False
    toggle_prob: float = 0.0  # per Gaussian: switch the feature off, or back on if it is off
    #: Colours the intent asks for (RGB); with ``recolor_prob`` per Gaussian, its colour is
    #: replaced by one of them (slightly varied) instead of taking HSL steps.
    palette: tuple[tuple[float, float, float], ...] = ()
    recolor_prob: float = 0.0
    #: With a palette: a colour changes only by a jump to one of its colours (with
    #: ``color_rate``), never by HSL steps or channel permutations.
    palette_only: bool = False
    #: Materials the intent names (:class:`~intuitf.explorer.hints.Hint`); with
    #: ``hint_prob`` per Gaussian, a Gaussian on a hinted material takes that hint's colour
    #: (slightly varied) and a height from its opacity band.
    hints: tuple[Hint, ...] = ()
    hint_prob: float = 0.0

    def forced(self) -> MutationParams:
        """Every attribute changes: used to push a near-duplicate away from its twin."""
        return replace(self, rate=1.0, mean_rate=1.0, color_rate=1.0, swap_prob=0.0)


def _mutate_color(
    color: tuple[float, float, float],
    rng: np.random.Generator,
    p: MutationParams,
    b: Bounds,
    own: tuple[float, float, float] | None = None,
) -> tuple[float, float, float]:
    # With palette_only, a jump is the only way a colour changes, at the colour rate: a stage
    # that does not judge the words keeps the colours they ask for (a hue step or a channel
    # permutation of gold is a green or pink tree that nothing rejects).
    jump = max(p.recolor_prob, p.color_rate) if p.palette_only else p.recolor_prob
    if p.palette and rng.random() < jump:
        # A jump to a colour the intent names: HSL steps take many generations to get there.
        # On a material the words give a colour (``own``), that colour, not another's.
        return b.sample_palette_color(rng, [own] if own is not None else p.palette)
    if p.palette and p.palette_only:
        return color
    if rng.random() < p.channel_prob:
        # Recombine the colour's own channels: a new hue of the same saturation and lightness.
        perm = rng.permutation(3)
        return b.clip_color(tuple(color[int(k)] for k in perm))
    h, s, lum = rgb_to_hsl(color)
    changed = False
    if rng.random() < p.color_rate:
        h = h + rng.normal(0.0, p.hue_step)
        h = h % 1.0 if b.hue_circular else _clip(h, b.hue)
        changed = True
    if rng.random() < p.color_rate:
        s = _clip(
            s + rng.normal(0.0, p.sl_step * (b.saturation[1] - b.saturation[0])), b.saturation
        )
        changed = True
    if rng.random() < p.color_rate:
        lum = _clip(
            lum + rng.normal(0.0, p.sl_step * (b.lightness[1] - b.lightness[0])), b.lightness
        )
        changed = True
    return b.clip_color(hsl_to_rgb(h, s, lum)) if changed else color


def mutate(
    tf: GaussianTF,
    rng: np.random.Generator,
    p: MutationParams,
    bounds: Bounds,
    only: Sequence[int] | None = None,
) -> GaussianTF:
    """A mutated copy of ``tf``: height, width, position and colour steps on free Gaussians.

    ``only`` restricts the mutation to those Gaussian indices (frozen ones still excluded).
    Colour mutation is, per individual, either a swap of two free Gaussians' colours (with
    ``swap_prob``) or per-Gaussian HSL steps with occasional channel recombination. With
    hints, a Gaussian drawn (``hint_prob``) to follow the hint of the material it sits on
    takes that hint's colour and a height from its band instead of those steps.
    """
    b = bounds
    gs = list(tf.gaussians)
    free = [i for i, g in enumerate(gs) if not g.frozen and (only is None or i in only)]
    if not free:
        return tf
    edit = edit_hint(p.hints) if p.hints else None
    if edit is not None:
        # An edit of selected features says what to do ("transparent", "gold"): each free
        # (selected) Gaussian moves that way, and nothing else about it changes.
        for i in free:
            gs[i] = edit_step(gs[i], edit, rng, b)
        return tf.with_gaussians(gs)
    hinted: dict[int, Hint] = {}
    for i in free:
        g = gs[i]
        mean, width, height = g.mean, g.width, g.height
        if rng.random() < p.mean_rate:
            mean = _clip(mean + rng.normal(0.0, p.mean_step * (b.mean[1] - b.mean[0])), b.mean)
        if rng.random() < p.rate:
            if p.additive:
                width = width + rng.normal(0.0, p.width_step * (b.width[1] - b.width[0]))
            else:
                width = width * math.exp(rng.normal(0.0, p.width_step))
            width = _clip(width, b.width)
        if rng.random() < p.rate:
            if p.additive:
                height = height + rng.normal(0.0, p.height_step * (b.height[1] - b.height[0]))
            else:
                height = max(height, b.height_floor) * math.exp(rng.normal(0.0, p.height_step))
            height = _clip(height, b.height)
        if p.toggle_prob and rng.random() < p.toggle_prob:
            # Which materials are visible at all is the biggest decision in a TF; small
            # multiplicative steps take many generations to hide or reveal one, a toggle
            # does it at once (hidden: height 0; shown: a fresh initial height). Hidden
            # means 0, not the floor: over a material as common as air, even 0.001 per
            # voxel adds up to a haze over the whole picture.
            lo, hi = b.height_init
            if height > lo:
                height = max(b.height[0], 0.0)
            else:
                height = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        # No random number is spent without hints, so such runs stay as they were.
        if p.hints and rng.random() < p.hint_prob:
            hint = hint_for(mean, p.hints)
            if hint is not None:
                hinted[i] = hint
                if hint.hidden:
                    height = max(b.height[0], 0.0)
                elif hint.height is not None:
                    height = sample_hint_height(rng, hint.height, b)
        gs[i] = replace(g, mean=mean, width=width, height=height)
    # The colour each Gaussian's material should have, by the words (no random number spent).
    own = {i: _hint_colour(gs[i].mean, p.hints) for i in free} if p.hints else {}
    swap = len(free) >= 2 and rng.random() < p.swap_prob
    if swap:
        i, j = (int(k) for k in rng.choice(free, size=2, replace=False))
        if own.get(i) is not None and own.get(j) is not None and own[i] != own[j]:
            swap = False  # the words gave these two materials their colours: keep them apart
        else:
            gs[i], gs[j] = replace(gs[i], color=gs[j].color), replace(gs[j], color=gs[i].color)
    if not swap:
        for i in free:
            gs[i] = replace(gs[i], color=_mutate_color(gs[i].color, rng, p, b, own.get(i)))
    for i, hint in hinted.items():
        if hint.color is not None:
            gs[i] = replace(gs[i], color=hint_color(rng, hint.color, b))
    return tf.with_gaussians(gs)


def _hint_colour(mean: float, hints: Sequence[Hint]) -> tuple[float, float, float] | None:
    """The colour the hint of the material at ``mean`` asks for (None: no hint, or no colour).

    Only hints placed on a material count (an edit's unplaced hint is drawn by ``hint_prob``).
    """
    h = hint_for(mean, [x for x in hints if x.center is not None])
    return None if h is None else h.color


def _swap(a: Gaussian, b: Gaussian, attrs: Sequence[str]) -> tuple[Gaussian, Gaussian]:
    da = {k: getattr(b, k) for k in attrs}
    db = {k: getattr(a, k) for k in attrs}
    return replace(a, **da), replace(b, **db)


def crossover(
    a: GaussianTF,
    b: GaussianTF,
    rng: np.random.Generator,
    *,
    attr_prob: float = 0.4,
    groups: Sequence[Sequence[str]] = PAPER_GROUPS,
    fallback_prob: float = 0.5,
    by_mean: bool = False,
) -> tuple[GaussianTF, GaussianTF]:
    """Two children that exchange Gaussian attributes between parents ``a`` and ``b``.

    Free Gaussians are paired by position (k-th lowest mean with k-th lowest mean, or with
    ``by_mean`` the pairing of least total distance between means). For each
    pair, every attribute group (e.g. colour; position; shape = width + height) is exchanged
    independently with ``attr_prob``; if none was, one random group is exchanged with
    ``fallback_prob``. Frozen Gaussians take no part. Children keep their parent's order.
    """
    for grp in groups:
        for k in grp:
            if k not in ATTRIBUTES:
                raise ValueError(f"Unknown Gaussian attribute {k!r}; use {ATTRIBUTES}.")
    ga, gb = list(a.gaussians), list(b.gaussians)
    ia = sorted((i for i, g in enumerate(ga) if not g.frozen), key=lambda i: ga[i].mean)
    ib = sorted((i for i, g in enumerate(gb) if not g.frozen), key=lambda i: gb[i].mean)
    for i, j in _pairs(ga, gb, ia, ib, by_mean):
        chosen = [grp for grp in groups if rng.random() < attr_prob]
        if not chosen and rng.random() < fallback_prob:
            chosen = [groups[int(rng.integers(len(groups)))]]
        attrs = [k for grp in chosen for k in grp]
        if attrs:
            ga[i], gb[j] = _swap(ga[i], gb[j], attrs)
    return a.with_gaussians(ga), b.with_gaussians(gb)


def _pairs(
    ga: Sequence[Gaussian], gb: Sequence[Gaussian], ia: list[int], ib: list[int], by_mean: bool
) -> list[tuple[int, int]]:
    """Which Gaussian of ``a`` exchanges attributes with which of ``b``.

    ``by_mean``: the pairing with the least total distance between means (so a feature meets
    the other parent's feature on the same material, even when one parent has an extra
    Gaussian below it); otherwise k-th lowest with k-th lowest, as the paper does.
    """
    if not by_mean or not ia or not ib:
        return list(zip(ia, ib, strict=False))
    cost = np.abs(np.subtract.outer([ga[i].mean for i in ia], [gb[j].mean for j in ib]))
    rows, cols = linear_sum_assignment(cost)
    return [(ia[r], ib[c]) for r, c in zip(rows, cols, strict=True)]


def roulette(fitness: Sequence[float], k: int, rng: np.random.Generator) -> np.ndarray:
    """``k`` indices drawn with replacement, each with probability proportional to its fitness."""
    w = np.asarray(fitness, dtype=np.float64)
    if w.ndim != 1 or w.size == 0 or not np.isfinite(w).all() or (w < 0).any():
        raise ValueError("Fitness must be a non-empty sequence of finite, non-negative values.")
    total = w.sum()
    p = w / total if total > 0 else np.full(w.size, 1.0 / w.size)
    return rng.choice(w.size, size=int(k), replace=True, p=p)


def elite_count(share: float, n: int) -> int:
    """How many elites a population of ``n`` keeps at ``share``: at least 1, at most n."""
    return min(n, max(1, int(share * n + 1e-9)))
