"""Material hints: what the intent's words say about single materials, as the Explorer sees it.

A hint says where a material sits in the (normalised) data range, what colour the user wants
it in and how opaque (a band of Gaussian heights). The Explorer never sees text or images: the
evaluator side turns words into hints (:mod:`intuitf.intent.hints`) the way it turns them
into a palette. The Explorer places part of its first population on them and, now and then,
draws a Gaussian's colour or height from the hint of the material it sits on. A hint without
a ``center`` applies to every free Gaussian (an edit of selected features: "make it gold").
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from intuitf.explorer.bounds import Bounds
from intuitf.tf.defaults import Material
from intuitf.tf.gaussian import Gaussian, GaussianTF

RGB = tuple[float, float, float]

#: What an edit may ask of the selected features' look.
EDIT_DIRECTIONS = (None, "fainter", "hidden", "stronger", "brighter", "darker")
#: Height factors per step of an edit that asks for less or more opacity, from the first
#: refined generation on: clearly fainter (at most a third, often a tenth: a thick wall is
#: still opaque at half its height) or clearly stronger.
FAINTER = (0.05, 0.35)
STRONGER = (1.5, 4.0)

#: A hint's colour is the colour the words name (orange, not gold): copies of it vary by
#: this part of a palette colour's variation (hue ±0.008, one standard deviation, where
#: ±0.02 took "orange" half-way to gold two times in five).
HINT_COLOR_VARIATION = 0.4

#: A Gaussian belongs to a hint when its mean is within this many of the hint's spreads...
_REACH = 2.5
#: ...or within this absolute distance (normalised units), whichever is larger.
_MIN_REACH = 0.03


#: The name of a hint made from a sketch's stroke (:mod:`intuitf.intent.strokes`).
STROKE = "stroke"


@dataclass(frozen=True)
class Hint:
    """One material the intent names: where it is, its colour and its opacity band."""

    name: str
    center: float | None = None
    spread: float = 0.03
    color: RGB | None = None
    height: tuple[float, float] | None = None
    hidden: bool = False
    #: An edit's direction for the selected features: "fainter", "hidden", "stronger",
    #: "brighter", "darker" (None: no opacity or lightness word).
    direction: str | None = None
    #: An edit that names no colour keeps the selected features' colours.
    keep_color: bool = False
    #: The values of the structure the hint was placed on (normalised, low to high), where
    #: they reach beyond its spreads: a Gaussian centred there shows that structure too.
    #: The engine's outer part holds values 0.31-0.59, its hint sits at 0.41 (where it meets
    #: the air), and its bulk at 0.56 was a leftover material that got any colour.
    reach: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.direction not in EDIT_DIRECTIONS:
            raise ValueError(
                f"A hint's direction must be one of {sorted(d for d in EDIT_DIRECTIONS if d)}"
                f" or None, got {self.direction!r}."
            )
        if self.center is not None and not 0.0 <= float(self.center) <= 1.0:
            raise ValueError(f"A hint's center must be within [0, 1], got {self.center!r}.")
        if not float(self.spread) > 0:
            raise ValueError(f"A hint's spread must be > 0, got {self.spread!r}.")
        if self.color is not None:
            c = tuple(float(v) for v in self.color)
            if len(c) != 3 or not all(0.0 <= v <= 1.0 for v in c):
                raise ValueError(f"A hint's colour must be three values in [0, 1], got {c!r}.")
            object.__setattr__(self, "color", c)
        if self.height is not None:
            lo, hi = (float(v) for v in self.height)
            if not 0.0 < lo <= hi <= 1.0:
                raise ValueError(
                    f"A hint's height band must be 0 < lo <= hi <= 1, got {self.height!r}."
                )
            object.__setattr__(self, "height", (lo, hi))
        if self.reach is not None:
            a, b = (float(v) for v in self.reach)
            if not 0.0 <= a <= b <= 1.0:
                raise ValueError(f"A hint's reach must be 0 <= lo <= hi <= 1, got {self.reach!r}.")
            object.__setattr__(self, "reach", (a, b))

    def reaches(self, mean: float) -> bool:
        """Whether a Gaussian at ``mean`` shows this hint's material."""
        if self.center is None:
            return True
        if self.reach is not None and self.reach[0] <= mean <= self.reach[1]:
            return True
        return abs(mean - self.center) <= max(_REACH * self.spread, _MIN_REACH)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "center": self.center,
            "spread": self.spread,
            "color": list(self.color) if self.color else None,
            "height": list(self.height) if self.height else None,
            "hidden": self.hidden,
            "direction": self.direction,
            "keep_color": self.keep_color,
            "reach": list(self.reach) if self.reach else None,
        }

    @classmethod
    def from_dict(cls, d: Mapping) -> Hint:
        return cls(
            name=str(d.get("name", "")),
            center=None if d.get("center") is None else float(d["center"]),
            spread=float(d.get("spread", 0.03)),
            color=None if d.get("color") is None else tuple(d["color"]),
            height=None if d.get("height") is None else tuple(d["height"]),
            hidden=bool(d.get("hidden", False)),
            direction=d.get("direction"),
            keep_color=bool(d.get("keep_color", False)),
            reach=None if d.get("reach") is None else tuple(d["reach"]),
        )


def hint_color(rng: np.random.Generator, color: RGB, bounds: Bounds) -> RGB:
    """A hint's ``color`` as a Gaussian takes it: the named colour, varied a little
    (:data:`HINT_COLOR_VARIATION`)."""
    return bounds.sample_palette_color(rng, [color], HINT_COLOR_VARIATION)


def as_hints(hints: Sequence[Hint | Mapping | object]) -> tuple[Hint, ...]:
    """Hints from :class:`Hint` objects, dicts, or objects with the same attributes."""
    out = []
    for h in hints:
        if isinstance(h, Hint):
            out.append(h)
        elif isinstance(h, Mapping):
            out.append(Hint.from_dict(h))
        elif hasattr(h, "to_explorer"):
            out.append(Hint.from_dict(h.to_explorer()))
        else:
            raise ValueError(f"Not a material hint: {h!r}.")
    return tuple(out)


def placed_hints(hints: Sequence[Hint]) -> list[Hint]:
    """The hints that show a material at a place on the values (what hinted TFs are built
    from)."""
    return [h for h in hints if h.center is not None and not h.hidden]


def from_strokes(hints: Sequence[Hint]) -> bool:
    """Whether every hint that shows a material at a place on the values (there is one)
    comes from a sketch's stroke."""
    placed = placed_hints(hints)
    return bool(placed) and all(h.name == STROKE for h in placed)


def hint_for(mean: float, hints: Sequence[Hint]) -> Hint | None:
    """The hint whose material a Gaussian at ``mean`` shows (the nearest), or None."""
    best, best_d = None, math.inf
    for h in hints:
        if not h.reaches(mean):
            continue
        d = 0.0 if h.center is None else abs(mean - h.center)
        if d < best_d:
            best, best_d = h, d
    return best


def sample_hint_height(
    rng: np.random.Generator, band: tuple[float, float], bounds: Bounds
) -> float:
    """A height drawn log-uniformly from ``band``, within the bounds."""
    lo, hi = band
    v = math.exp(rng.uniform(math.log(lo), math.log(hi)))
    return min(bounds.height[1], max(bounds.height[0], v))


def hinted_tf(
    rng: np.random.Generator,
    hints: Sequence[Hint],
    materials: Sequence[Material],
    n_gaussians: int,
    bounds: Bounds,
    *,
    value_range: tuple[float, float] | None = None,
    color: Callable[[np.random.Generator], RGB] | None = None,
    hide_prob: float = 0.7,
) -> GaussianTF:
    """A TF that shows what the hints ask for: one Gaussian per placed hint, the rest quiet.

    Each hint with a ``center`` gets a Gaussian near it (about its spread wide), in its colour
    (slightly varied; ``color`` when the hint names none) and with a height from its band
    (the bounds' initial range when it names none), no wider than keeps its tail off the
    values of the other hints' structures (:data:`NEIGHBOUR_TAIL`). With more hints than
    Gaussians a random subset is used. A material within a hint's ``reach`` but beyond its
    spreads gets a Gaussian of that hint too. Gaussians left over go to the volume's other
    ``materials`` and are hidden (height 0) with ``hide_prob``, else faint: what the words
    did not name stays out of the way, but remains one toggle from view.
    """
    color = color or bounds.sample_color
    # A hidden material needs no Gaussian (not showing it is the point); it still keeps
    # the leftover Gaussians away and pulls mutations there to height 0.
    avoid = [h for h in hints if h.center is not None]
    placed = placed_hints(hints)
    if len(placed) > n_gaussians:
        pick = sorted(int(i) for i in rng.choice(len(placed), size=n_gaussians, replace=False))
        placed = [placed[i] for i in pick]
    gs: list[Gaussian] = []
    for h in placed:
        mean = min(bounds.mean[1], max(bounds.mean[0], h.center + rng.normal(0.0, 0.2 * h.spread)))
        width = min(
            bounds.width[1], max(bounds.width[0], h.spread * math.exp(rng.normal(0.0, 0.3)))
        )
        band = h.height or bounds.height_init
        height = 0.0 if h.hidden else sample_hint_height(rng, band, bounds)
        rgb = hint_color(rng, h.color, bounds) if h.color else color(rng)
        width = _apart(mean, width, h, placed, bounds)
        gs.append(Gaussian(mean, width, height, rgb))
    # A material inside a placed structure's values but beyond its Gaussian's span (the
    # engine's outer part meets the air at 0.41, its bulk is at 0.56) is that structure too:
    # a Gaussian of its own, in the structure's colour and look, where one is left.
    for m in materials:
        if len(gs) >= n_gaussians:
            break
        h = hint_for(m.center, placed)
        if h is None or h.reach is None or abs(m.center - h.center) <= _REACH * h.spread:
            continue
        width = _apart(m.center, min(bounds.width[1], max(bounds.width[0], m.spread)), h, placed,
                       bounds)  # fmt: skip
        rgb = hint_color(rng, h.color, bounds) if h.color else color(rng)
        height = sample_hint_height(rng, h.height or bounds.height_init, bounds)
        gs.append(Gaussian(float(m.center), float(width), height, rgb))
    others = [m for m in materials if all(not h.reaches(m.center) for h in avoid)]
    order = list(rng.permutation(len(others))) if others else []
    while len(gs) < n_gaussians:
        if order:
            m = others[int(order.pop())]
            mean, width = m.center, min(bounds.width[1], max(bounds.width[0], m.spread))
        else:
            # Anywhere but on a hinted material (that one is already as the words say).
            for _ in range(10):
                mean = float(rng.uniform(*bounds.mean))
                if not any(h.reaches(mean) for h in avoid):
                    break
            width = bounds.sample_width(rng)
        if rng.random() < hide_prob:
            height = 0.0
        else:
            lo = bounds.height_init[0]
            height = sample_hint_height(rng, (lo, max(lo, 0.03)), bounds)
        gs.append(Gaussian(float(mean), float(width), height, color(rng)))
    return GaussianTF(tuple(sorted(gs, key=lambda g: g.mean)), value_range=value_range)


#: A hinted Gaussian of the first population gives the values of another named material at
#: most this share of its height with its tail. An orange "inner part" 0.08 wide gave the
#: engine's outer part's highest values 14 % of its height: the blue outer part showed
#: orange faces (ΔE2000 30 against 6 at 2.2 %).
NEIGHBOUR_TAIL = 0.025


def _apart(mean: float, width: float, hint: Hint, placed: Sequence[Hint], bounds: Bounds) -> float:
    """``width`` narrowed so that a Gaussian of ``hint`` at ``mean`` keeps its tail off the
    values of the other ``placed`` hints' structures (their ``reach``, to ``NEIGHBOUR_TAIL``),
    not below the bounds.

    Only structures whose values are known count: a sketch's strokes on one material (the
    tooth's crown top and middle) overlap on purpose. Narrowed by each other's spreads as
    well, the tooth sketch's crown middle went from ΔE2000 9.4 to 13.9 with the labelling
    oracle (6 seeds).
    """
    for other in placed:
        span = other.reach
        if other is hint or span is None or (other.color == hint.color and other.color):
            continue
        gap = max(span[0] - mean, mean - span[1])
        if gap > 0.0:
            width = min(width, max(bounds.width[0], widest_for_tail(gap, 1.0, NEIGHBOUR_TAIL)))
    return width


def widest_for_tail(distance: float, height: float, tail: float) -> float:
    """The width of the widest Gaussian of ``height`` whose tail at ``distance`` from its
    mean is ``tail`` (< ``height``)."""
    return distance / math.sqrt(2.0 * math.log(height / tail))


def edit_hint(hints: Sequence[Hint]) -> Hint | None:
    """The hint of an edit (no place: it applies to the selected features), if any."""
    for h in hints:
        if h.center is None and (h.direction or h.keep_color or h.color or h.hidden):
            return h
    return None


def edit_step(g: Gaussian, hint: Hint, rng: np.random.Generator, bounds: Bounds) -> Gaussian:
    """``g`` moved the way an edit asks: opacity and colour, never its place or width.

    "fainter" multiplies the height by a factor in ``FAINTER``, "stronger" by one in
    ``STRONGER`` (from at least the bounds' initial low), "hidden" sets it to 0; with no such
    word the height takes a small step. A named colour is taken (slightly varied); "brighter"
    and "darker" move the lightness; otherwise the colour stays as it is.
    """
    from intuitf.explorer.bounds import hsl_to_rgb, rgb_to_hsl

    h = g.height
    d = hint.direction
    if hint.hidden or d == "hidden":
        h = 0.0
    elif d == "fainter":
        h = h * math.exp(rng.uniform(math.log(FAINTER[0]), math.log(FAINTER[1])))
    elif d == "stronger":
        base = max(h, bounds.height_init[0])
        h = base * math.exp(rng.uniform(math.log(STRONGER[0]), math.log(STRONGER[1])))
    else:
        h = h * math.exp(rng.normal(0.0, 0.15))
    h = min(bounds.height[1], max(bounds.height[0], h))
    color = g.color
    if hint.color is not None:
        color = hint_color(rng, hint.color, bounds)
    elif d in ("brighter", "darker"):
        hue, sat, lum = rgb_to_hsl(g.color)
        step = rng.uniform(0.08, 0.25) * (1.0 if d == "brighter" else -1.0)
        color = bounds.clip_color(hsl_to_rgb(hue, sat, min(1.0, max(0.0, lum + step))))
    return replace(g, height=float(h), color=color)


#: A Gaussian centred elsewhere may give the edge of a hidden material's values (below)
#: at most this opacity per voxel length with its tail.
HIDDEN_EPS = 2e-3
#: A Gaussian centred on a hidden material's values is switched off when its height is above
#: this, however faint. A ray crosses the air of a 256³ box over up to 443 voxels: a height of
#: 2e-3 there sums to 40 % alpha, and such a faint red Gaussian on a head CT's air drew the
#: whole box as a red fog; 5e-5 sums to 2 % at most. (The same bound on the tails of Gaussians
#: centred elsewhere narrowed wide ones, and the tooth sketch's crown lost its red: ΔE2000
#: 8.7 -> 22.7 over 12 seeds.) The tails of those must keep to it at the hint's center, where
#: the material's voxels mostly are: a faint red Gaussian at 0.13 gave the chest CT's air
#: (0.0) 5e-4 and drew the box as a red veil over the body.
HIDDEN_CORE_EPS = 5e-5
#: ... from one spread below its hint's center to this many above (the background's hint
#: reaches from its mode up to just below the first material: its noise too).
HIDDEN_REACH = 2.5


def quiet_hidden(tf: GaussianTF, hints: Sequence[Hint], bounds: Bounds) -> GaussianTF:
    """``tf`` with no free Gaussian showing a hidden material (the background, unless the
    words ask for it).

    A hidden material's values are its hint's center from one spread below to
    ``HIDDEN_REACH`` spreads above. A free Gaussian centred on them is switched off (unless
    its height is below ``HIDDEN_CORE_EPS``); one centred elsewhere that gives their edge more
    than ``HIDDEN_EPS`` of opacity, or their center more than ``HIDDEN_CORE_EPS``, is narrowed
    until it does not, or switched off when it would have to be narrower than the bounds
    allow. Over a material as common as air, even a faint Gaussian is a fog over the whole
    volume box.
    """
    hidden = [h for h in hints if h.hidden and h.center is not None]
    if not hidden:
        return tf
    gs = list(tf.gaussians)
    changed = False
    for i, g in enumerate(gs):
        if g.frozen or g.height <= HIDDEN_CORE_EPS:
            continue
        for h in hidden:
            lo, hi = h.center - h.spread, h.center + HIDDEN_REACH * h.spread
            nearest = min(hi, max(lo, g.mean))
            gap = abs(g.mean - nearest)
            if gap == 0.0:
                g = replace(g, height=0.0)
                changed = True
                break
            # Two bounds: the tail may give the edge of the hidden values ``HIDDEN_EPS``, and
            # the value the material mostly holds (its hint's center) ``HIDDEN_CORE_EPS``:
            # most of the air sits there, so the tail's opacity there is the box's fog.
            w_max = math.inf
            for dist, eps in ((gap, HIDDEN_EPS), (abs(g.mean - h.center), HIDDEN_CORE_EPS)):
                if g.height * math.exp(-(dist**2) / (2.0 * g.width**2)) > eps:
                    w_max = min(w_max, widest_for_tail(dist, g.height, eps))
            if w_max == math.inf:
                continue
            if w_max >= bounds.width[0]:
                g = replace(g, width=float(min(g.width, w_max)))
            else:
                g = replace(g, height=0.0)
            changed = True
        gs[i] = g
    return tf.with_gaussians(gs) if changed else tf


#: A named, shown material's strongest Gaussian in its colour keeps at least this share of its
#: hint's band's low end (:func:`keep_shown`): a fade to nothing is undone, a thinning is not.
#: At the whole low end (1.0) the offline judge's bonsai pot went from ΔE2000 9.2 ± 0.6 to
#: 11.6 ± 0.8 (36 seeds); at 0.3 it is 9.7 ± 1.0.
SHOWN_FLOOR = 0.3
#: A Gaussian shows a hint's material in the hint's colour when their RGB distance is at most
#: this (copies of a hint vary by far less; mutations drift further).
SHOWN_COLOR_REACH = 0.25


def _in_color(rgb: RGB, asked: RGB | None) -> bool:
    return asked is None or math.dist(rgb, asked) <= SHOWN_COLOR_REACH


def keep_shown(tf: GaussianTF, hints: Sequence[Hint], bounds: Bounds) -> GaussianTF:
    """``tf`` with every material the words name and show still shown: where no free Gaussian
    on a placed, shown hint (with a height band, no edit direction), in its colour
    (:data:`SHOWN_COLOR_REACH`), reaches :data:`SHOWN_FLOOR` of its band's low end, the
    strongest of them is raised to that.

    The counterpart of :func:`quiet_hidden`. A judge that weighs only colours may fade a named
    structure to nothing: the labelling oracle faded the bonsai's pot to a mean opacity of
    0.004, and only its rim's colour showed. A Gaussian of another colour there is left as it
    is: it does not show the material as asked, and raising it (the first population's
    histogram seeds put the tooth sketch's stroke colours on its dentin in any order) worsened
    the sketch's crown top and root. So is a Gaussian no longer on the hint's values (moved
    away), and a hint no free Gaussian reaches; a Gaussian counts for the nearest hint it
    reaches (:func:`hint_for`).
    """
    shown = [h for h in hints if h.center is not None and h.height is not None]
    shown = [h for h in shown if not h.hidden and h.direction is None]
    if not shown:
        return tf
    gs = list(tf.gaussians)
    # A Gaussian counts for the hint whose material it shows, the nearest one, when it shows
    # it in (about) the hint's colour: another colour there is not what was asked.
    owner = [None if g.frozen else hint_for(g.mean, shown) for g in gs]
    changed = False
    for h in shown:
        on = [i for i, g in enumerate(gs) if owner[i] is h and _in_color(g.color, h.color)]
        if not on:
            continue
        i = max(on, key=lambda k: gs[k].height)
        floor = min(bounds.height[1], max(bounds.height[0], SHOWN_FLOOR * h.height[0]))
        if gs[i].height < floor:
            gs[i] = replace(gs[i], height=float(floor))
            changed = True
    return tf.with_gaussians(gs) if changed else tf


def as_the_words_say(tf: GaussianTF, hints: Sequence[Hint], bounds: Bounds) -> GaussianTF:
    """``tf`` with what the words name and show kept shown (:func:`keep_shown`) and what they
    hide kept hidden (:func:`quiet_hidden`), hiding last: a Gaussian raised on values that
    are also a hidden material's (a faded gold one at the top of the air's values, nearest
    the leaves) is switched off again, never left to paint the volume's box."""
    return quiet_hidden(keep_shown(tf, hints, bounds), hints, bounds)
