"""Carry a transfer function from the volume it was designed for to another volume.

A TF's Gaussians sit at values of *its* volume. Another scanner, protocol or body part puts the
same material elsewhere on the normalised [0, 1] scale (a foot CT in 8 bits, a head CT in
12 bits with another window), so copying the numbers would paint bone on soft tissue. Instead,
both histograms are read for their materials (:func:`intuitf.tf.defaults.find_materials`:
peaks above the background and the long tail where bone lives), the materials are matched in
order, and values are carried by a monotone piecewise-linear map through the matched pairs:

    background cut ↦ background cut, material i of the reference ↦ its partner, 1 ↦ 1

Matching is an order-keeping alignment (like aligning two sequences) whose cost compares where
each material sits in its volume: its position above the background on the value scale and
its quantile among the foreground voxels; a material with no good partner is left out. A
Gaussian then moves with its value (its width scaled by the map's slope there), keeping its
height and colour: "bone" lands on bone, "skin" on skin.

Without the reference volume's histogram, values are carried in the data's own units when
both sides know them (e.g. Hounsfield units), else kept on the normalised scale.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from intuitf.tf.defaults import Material, background_cutoff, find_materials
from intuitf.tf.gaussian import MEAN_RANGE, WIDTH_RANGE, Gaussian, GaussianTF

#: Cost of leaving a material of either side without a partner.
_SKIP = 0.3


@dataclass(frozen=True)
class ValueMap:
    """A monotone map of normalised values, from reference to target, and how it was made."""

    xs: tuple[float, ...]
    ys: tuple[float, ...]
    pairs: tuple[tuple[float, float], ...] = ()
    how: str = "materials"

    def __call__(self, v: float | np.ndarray) -> float | np.ndarray:
        out = np.interp(v, self.xs, self.ys)
        return float(out) if np.ndim(out) == 0 else out

    def slope(self, v: float, h: float) -> float:
        h = max(h, 1e-3)
        lo, hi = max(0.0, v - h), min(1.0, v + h)
        if hi <= lo:
            return 1.0
        return float((self(hi) - self(lo)) / (hi - lo))

    def to_dict(self) -> dict:
        return {"how": self.how, "xs": list(self.xs), "ys": list(self.ys),
                "pairs": [list(p) for p in self.pairs]}  # fmt: skip


def _foreground_cdf(counts: np.ndarray, cut: float) -> tuple[np.ndarray, np.ndarray]:
    c = np.asarray(counts, np.float64)
    n = c.size
    centers = (np.arange(n) + 0.5) / n
    fg = np.where(centers > cut, c, 0.0)
    if fg.sum() <= 0:
        fg = c.copy()
    cdf = np.cumsum(fg) / max(fg.sum(), 1e-12)
    return centers, cdf


def _describe(mats: list[Material], counts: np.ndarray, cut: float) -> np.ndarray:
    """Per material: (position between the background and the top of the foreground (its
    99.9th percentile, so a few extreme voxels do not squash the scale), foreground quantile)."""
    centers, cdf = _foreground_cdf(counts, cut)
    top = float(centers[min(len(centers) - 1, int(np.searchsorted(cdf, 0.999)))])
    out = []
    for m in mats:
        pos = (m.center - cut) / max(1e-6, top - cut)
        q = float(np.interp(m.center, centers, cdf))
        out.append((float(np.clip(pos, 0, 1)), q))
    return np.asarray(out, np.float64).reshape(-1, 2)


def _align(a: np.ndarray, b: np.ndarray) -> list[tuple[int, int]]:
    """Order-keeping pairs (i, j) of minimum total cost (skips cost ``_SKIP`` each)."""
    n, m = len(a), len(b)
    cost = np.full((n + 1, m + 1), np.inf)
    back = np.zeros((n + 1, m + 1), np.int8)  # 0 pair, 1 skip a, 2 skip b
    cost[0, :] = np.arange(m + 1) * _SKIP
    cost[:, 0] = np.arange(n + 1) * _SKIP
    back[0, 1:] = 2
    back[1:, 0] = 1
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            d = float(np.abs(a[i - 1] - b[j - 1]).sum())
            options = (cost[i - 1, j - 1] + d, cost[i - 1, j] + _SKIP, cost[i, j - 1] + _SKIP)
            k = int(np.argmin(options))
            cost[i, j], back[i, j] = options[k], k
    pairs = []
    i, j = n, m
    while i > 0 or j > 0:
        k = back[i, j]
        if k == 0:
            pairs.append((i - 1, j - 1))
            i, j = i - 1, j - 1
        elif k == 1:
            i -= 1
        else:
            j -= 1
    return pairs[::-1]


def _monotone(points: list[tuple[float, float]]) -> tuple[list[float], list[float]]:
    """Anchors sorted by x, keeping only those that go up in both x and y."""
    xs: list[float] = []
    ys: list[float] = []
    for x, y in sorted(points):
        if xs and (x <= xs[-1] + 1e-6 or y <= ys[-1] + 1e-6):
            continue
        xs.append(float(x))
        ys.append(float(y))
    return xs, ys


def _quantile(counts: np.ndarray, cut: float, q: float) -> float:
    centers, cdf = _foreground_cdf(counts, cut)
    return float(centers[min(len(centers) - 1, int(np.searchsorted(cdf, q)))])


def material_map(ref_counts: np.ndarray, target_counts: np.ndarray) -> ValueMap:
    """The value map that takes each material of the reference histogram to its partner in
    the target's (both histograms over normalised [0, 1]).

    Anchors: the background cut-offs; the dominant histogram peak of each; the other peaks,
    aligned in order below and above it; and the top of the foreground (its 99th and 99.9th percentiles, where dense material such as bone sits
    in a long tail without a peak of its own).
    """
    rc, tc = np.asarray(ref_counts, np.float64), np.asarray(target_counts, np.float64)
    cut_r, cut_t = background_cutoff(rc), background_cutoff(tc)
    peaks_r = [m for m in find_materials(rc, max_materials=6) if m.fraction > 0]
    peaks_t = [m for m in find_materials(tc, max_materials=6) if m.fraction > 0]
    pairs: list[tuple[float, float]] = []
    if peaks_r and peaks_t:
        # The dominant material of each (soft tissue in most scans) anchors the rest: the
        # peaks below it are aligned with those below it, the peaks above with those above.
        i0 = max(range(len(peaks_r)), key=lambda i: peaks_r[i].fraction)
        j0 = max(range(len(peaks_t)), key=lambda j: peaks_t[j].fraction)
        da, db = _describe(peaks_r, rc, cut_r), _describe(peaks_t, tc, cut_t)
        below = _align(da[:i0], db[:j0])
        above = [(i0 + 1 + i, j0 + 1 + j) for i, j in _align(da[i0 + 1 :], db[j0 + 1 :])]
        pairs = [(peaks_r[i].center, peaks_t[j].center) for i, j in [*below, (i0, j0), *above]]
    for q in (0.99, 0.999):
        pairs.append((_quantile(rc, cut_r, q), _quantile(tc, cut_t, q)))
    points = [(0.0, 0.0), (1.0, 1.0), *pairs]
    if cut_r > 0 and cut_t > 0:
        points.append((cut_r, cut_t))
    xs, ys = _monotone(points)
    kept = tuple((x, y) for x, y in pairs if x in xs)
    return ValueMap(tuple(xs), tuple(ys), kept, "materials")


def unit_map(
    ref_range: tuple[float, float] | None, target_range: tuple[float, float] | None
) -> ValueMap:
    """Values carried in the data's units (when both ranges are known), else unchanged."""
    if not ref_range or not target_range:
        return ValueMap((0.0, 1.0), (0.0, 1.0), (), "identity")
    (r0, r1), (t0, t1) = ref_range, target_range
    if r1 <= r0 or t1 <= t0:
        return ValueMap((0.0, 1.0), (0.0, 1.0), (), "identity")
    # y = (r0 + x (r1 - r0) - t0) / (t1 - t0), clamped to [0, 1]; as anchors.
    xs = np.linspace(0.0, 1.0, 65)
    ys = np.clip((r0 + xs * (r1 - r0) - t0) / (t1 - t0), 0.0, 1.0)
    return ValueMap(tuple(float(x) for x in xs), tuple(float(y) for y in ys), (), "units")


def carry_tf(tf: GaussianTF, value_map: ValueMap, *, name: str | None = None) -> GaussianTF:
    """``tf`` with every Gaussian moved by ``value_map`` (width scaled by its slope there)."""
    gs = []
    for g in tf.gaussians:
        mean = float(np.clip(value_map(g.mean), *MEAN_RANGE))
        k = float(np.clip(value_map.slope(g.mean, max(g.width, 0.01)), 0.2, 5.0))
        width = float(np.clip(g.width * k, *WIDTH_RANGE))
        gs.append(Gaussian(mean, width, g.height, g.color, g.frozen))
    return replace(tf, gaussians=tuple(gs), name=name if name is not None else tf.name)


def transfer_tf(
    tf: GaussianTF,
    target_counts: np.ndarray,
    *,
    ref_counts: np.ndarray | None = None,
    ref_range: tuple[float, float] | None = None,
    target_range: tuple[float, float] | None = None,
) -> tuple[GaussianTF, ValueMap]:
    """Carry ``tf`` to a volume whose histogram is ``target_counts``: by materials when the
    reference volume's histogram ``ref_counts`` is known, else by units (see module notes).
    The result speaks the target's value range."""
    if ref_counts is not None and np.asarray(ref_counts).sum() > 0:
        vm = material_map(np.asarray(ref_counts), np.asarray(target_counts))
    else:
        vm = unit_map(ref_range or tf.value_range, target_range)
    out = carry_tf(tf, vm, name="carried")
    return replace(out, value_range=target_range), vm
