"""Where the Explorer may put a Gaussian: parameter bounds, colour in HSL, and their sampling."""

from __future__ import annotations

import colorsys
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from intuitf.tf.gaussian import HEIGHT_RANGE, MEAN_RANGE, WIDTH_RANGE, GaussianTF

Range = tuple[float, float]


def rgb_to_hsl(rgb: Sequence[float]) -> tuple[float, float, float]:
    """(hue, saturation, lightness) of an RGB colour, all in [0, 1]."""
    h, lum, s = colorsys.rgb_to_hls(*(float(c) for c in rgb))
    return h, s, lum


def hsl_to_rgb(h: float, s: float, lum: float) -> tuple[float, float, float]:
    """RGB in [0, 1] of a colour given as (hue, saturation, lightness)."""
    r, g, b = colorsys.hls_to_rgb(h % 1.0, lum, s)
    return (min(1.0, max(0.0, r)), min(1.0, max(0.0, g)), min(1.0, max(0.0, b)))


def _clip(v: float, r: Range) -> float:
    return min(r[1], max(r[0], float(v)))


@dataclass(frozen=True)
class Bounds:
    """Box the Explorer samples and clips Gaussian parameters to (normalised units).

    ``height`` is the hard range; new heights are drawn log-uniformly from ``height_init``,
    because opacity-per-voxel values that make readable pictures are mostly 0.005–0.5 and a
    large opaque Gaussian hides everything behind it. ``height_floor`` is the smallest height
    that log-space steps and encodings distinguish from zero. Colour bounds are in HSL, like
    the authors' prototype; the hue range is circular only when it is the full [0, 1].
    """

    mean: Range = (0.0, 1.0)
    width: Range = (0.005, 0.08)
    height: Range = (0.0, 1.0)
    height_init: Range = (0.005, 0.5)
    height_floor: float = 1e-3
    hue: Range = (0.0, 1.0)
    saturation: Range = (0.0, 1.0)
    lightness: Range = (0.3, 0.95)

    def __post_init__(self) -> None:
        checks = {
            "mean": (self.mean, MEAN_RANGE),
            "width": (self.width, WIDTH_RANGE),
            "height": (self.height, HEIGHT_RANGE),
            "height_init": (self.height_init, HEIGHT_RANGE),
            "hue": (self.hue, (0.0, 1.0)),
            "saturation": (self.saturation, (0.0, 1.0)),
            "lightness": (self.lightness, (0.0, 1.0)),
        }
        for name, (r, valid) in checks.items():
            lo, hi = (float(v) for v in r)
            if not (valid[0] <= lo <= hi <= valid[1]):
                raise ValueError(f"Bounds.{name} must be a range within {valid}, got {r!r}.")
            object.__setattr__(self, name, (lo, hi))
        if not 0.0 < self.height_floor <= self.height_init[0] or self.height_init[0] <= 0:
            raise ValueError("Bounds need 0 < height_floor <= height_init[0].")

    @property
    def hue_circular(self) -> bool:
        return self.hue == (0.0, 1.0)

    # -- checks and clipping --------------------------------------------------------------
    def clip_color(self, rgb: Sequence[float]) -> tuple[float, float, float]:
        """The colour moved into the HSL box (unchanged when it is already inside)."""
        h, s, lum = rgb_to_hsl(rgb)
        if self.contains_hsl(h, s, lum):
            return tuple(float(c) for c in rgb)  # type: ignore[return-value]
        return hsl_to_rgb(_clip(h, self.hue), _clip(s, self.saturation), _clip(lum, self.lightness))

    def contains_hsl(self, h: float, s: float, lum: float, tol: float = 1e-6) -> bool:
        # Achromatic colours (grey, white) have no hue: any hue bound holds for them.
        hue_ok = s <= tol or self.hue[0] - tol <= h <= self.hue[1] + tol
        return (
            hue_ok
            and self.saturation[0] - tol <= s <= self.saturation[1] + tol
            and self.lightness[0] - tol <= lum <= self.lightness[1] + tol
        )

    def contains(self, tf: GaussianTF, tol: float = 1e-6) -> bool:
        """Whether every Gaussian of ``tf`` lies inside these bounds."""
        for g in tf.gaussians:
            if not (self.mean[0] - tol <= g.mean <= self.mean[1] + tol):
                return False
            if not (self.width[0] - tol <= g.width <= self.width[1] + tol):
                return False
            if not (self.height[0] - tol <= g.height <= self.height[1] + tol):
                return False
            # colorsys round trips lose ~1e-16; a looser tolerance for colour.
            if not self.contains_hsl(*rgb_to_hsl(g.color), tol=1e-4):
                return False
        return True

    def covering(self, tfs: Sequence[GaussianTF]) -> Bounds:
        """These bounds widened just enough to hold every Gaussian of ``tfs``.

        A run that starts from given TFs keeps them reachable and never clips them by surprise.
        """
        if not tfs:
            return self
        gs = [g for tf in tfs for g in tf.gaussians]
        hsl = [rgb_to_hsl(g.color) for g in gs]
        chromatic = [h for h, s, _ in hsl if s > 1e-6]

        def widen(r: Range, values: list[float]) -> Range:
            return (min([r[0], *values]), max([r[1], *values])) if values else r

        return Bounds(
            mean=widen(self.mean, [g.mean for g in gs]),
            width=widen(self.width, [g.width for g in gs]),
            height=widen(self.height, [g.height for g in gs]),
            height_init=self.height_init,
            height_floor=self.height_floor,
            hue=widen(self.hue, chromatic),
            saturation=widen(self.saturation, [s for _, s, _ in hsl]),
            lightness=widen(self.lightness, [lum for _, _, lum in hsl]),
        )

    # -- sampling --------------------------------------------------------------------------
    def sample_height(self, rng: np.random.Generator) -> float:
        lo, hi = self.height_init
        return _clip(math.exp(rng.uniform(math.log(lo), math.log(hi))), self.height)

    def sample_width(self, rng: np.random.Generator) -> float:
        # Log-uniform: narrow and wide features are equally likely in relative terms.
        lo, hi = self.width
        return math.exp(rng.uniform(math.log(lo), math.log(hi)))

    def sample_color(self, rng: np.random.Generator) -> tuple[float, float, float]:
        h = rng.uniform(*self.hue)
        s = rng.uniform(*self.saturation)
        lum = rng.uniform(*self.lightness)
        return hsl_to_rgb(h, s, lum)

    def sample_palette_color(
        self,
        rng: np.random.Generator,
        palette: Sequence[Sequence[float]],
        variation: float = 1.0,
    ) -> tuple[float, float, float]:
        """One of ``palette``'s colours, slightly varied (in HSL) and moved into the bounds.

        The variation (hue ±0.02, saturation and lightness ±0.05, one standard deviation,
        times ``variation``) keeps copies of one colour apart, so duplicate removal does not
        reject them.
        """
        h, s, lum = rgb_to_hsl(palette[int(rng.integers(len(palette)))])
        h = h + rng.normal(0.0, 0.02 * variation)
        h = h % 1.0 if self.hue_circular else _clip(h, self.hue)
        s = _clip(s + rng.normal(0.0, 0.05 * variation), self.saturation)
        lum = _clip(lum + rng.normal(0.0, 0.05 * variation), self.lightness)
        return self.clip_color(hsl_to_rgb(h, s, lum))

    # -- serialisation ---------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "mean": list(self.mean),
            "width": list(self.width),
            "height": list(self.height),
            "height_init": list(self.height_init),
            "height_floor": self.height_floor,
            "hue": list(self.hue),
            "saturation": list(self.saturation),
            "lightness": list(self.lightness),
        }

    @classmethod
    def from_dict(cls, d: dict) -> Bounds:
        ranges = {k: tuple(v) for k, v in d.items() if k != "height_floor"}
        return cls(**ranges, height_floor=float(d.get("height_floor", 1e-3)))
