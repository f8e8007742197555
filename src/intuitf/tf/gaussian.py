"""The Gaussian-mixture transfer function: the genome the Explorer evolves.

A :class:`GaussianTF` is N Gaussians over the normalised scalar domain [0, 1]. Each Gaussian
has a mean, a width (standard deviation), a height and an RGB colour. The height is an opacity
per unit length: the alpha a one-voxel-long segment of that material takes (the convention of
VTK's ``ScalarOpacityUnitDistance`` set to one voxel). Renderers correct it for their sampling
step with ``1 - (1 - a) ** (step / unit)``, so a picture does not change with the sampling rate.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from intuitf.errors import TransferFunctionError

TF_FORMAT = "intuitf.gaussian-tf"
TF_VERSION = 1

MIN_GAUSSIANS = 1
MAX_GAUSSIANS = 16
DEFAULT_GAUSSIANS = 5

#: Valid ranges of each Gaussian's parameters (normalised units).
MEAN_RANGE = (0.0, 1.0)
WIDTH_RANGE = (0.002, 0.5)
HEIGHT_RANGE = (0.0, 1.0)


def _check_range(name: str, value: float, bounds: tuple[float, float]) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan  # not a number at all: reported below like any other bad value
    if not math.isfinite(v) or v < bounds[0] or v > bounds[1]:
        raise TransferFunctionError(
            f"Gaussian {name} must be within [{bounds[0]}, {bounds[1]}], got {value!r}."
        )
    return v


@dataclass(frozen=True)
class Gaussian:
    """One component: ``height * exp(-(s - mean)**2 / (2 * width**2))`` painted ``color``.

    ``frozen`` Gaussians are left untouched by the Explorer (refinement stage).
    """

    mean: float
    width: float
    height: float
    color: tuple[float, float, float]
    frozen: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "mean", _check_range("mean", self.mean, MEAN_RANGE))
        object.__setattr__(self, "width", _check_range("width", self.width, WIDTH_RANGE))
        object.__setattr__(self, "height", _check_range("height", self.height, HEIGHT_RANGE))
        try:
            col = tuple(float(c) for c in self.color)
        except (TypeError, ValueError):
            col = ()  # not numbers: reported below
        if len(col) != 3 or not all(math.isfinite(c) and 0.0 <= c <= 1.0 for c in col):
            raise TransferFunctionError(
                f"Gaussian color must be three values in [0, 1], got {self.color!r}."
            )
        object.__setattr__(self, "color", col)
        object.__setattr__(self, "frozen", bool(self.frozen))

    def evaluate(self, s: np.ndarray) -> np.ndarray:
        """Opacity density this Gaussian contributes at normalised values ``s``."""
        return self.height * np.exp(-0.5 * ((s - self.mean) / self.width) ** 2)

    def to_dict(self) -> dict:
        return {
            "mean": self.mean,
            "width": self.width,
            "height": self.height,
            "color": list(self.color),
            "frozen": self.frozen,
        }

    @classmethod
    def from_dict(cls, d: dict) -> Gaussian:
        try:
            return cls(
                mean=d["mean"],
                width=d["width"],
                height=d["height"],
                color=tuple(d["color"]),
                frozen=d.get("frozen", False),
            )
        except (KeyError, TypeError) as exc:
            raise TransferFunctionError(f"A Gaussian entry is malformed ({exc!r}): {d!r}") from exc


@dataclass(frozen=True)
class GaussianTF:
    """A transfer function made of 1–16 Gaussians.

    ``value_range`` optionally records the original data units that [0, 1] maps to, so
    exports can speak those units. ``name`` is free text.
    """

    gaussians: tuple[Gaussian, ...]
    value_range: tuple[float, float] | None = None
    name: str = ""
    metadata: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        gs = tuple(self.gaussians)
        if not MIN_GAUSSIANS <= len(gs) <= MAX_GAUSSIANS:
            raise TransferFunctionError(
                f"A transfer function has {MIN_GAUSSIANS}–{MAX_GAUSSIANS} Gaussians, got {len(gs)}."
            )
        if not all(isinstance(g, Gaussian) for g in gs):
            raise TransferFunctionError("GaussianTF.gaussians must hold Gaussian objects.")
        object.__setattr__(self, "gaussians", gs)
        if self.value_range is not None:
            try:
                lo, hi = (float(v) for v in self.value_range)
            except (TypeError, ValueError):
                lo = hi = math.nan  # not a pair of numbers: reported below
            if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
                raise TransferFunctionError(
                    f"value_range must be (low, high) with high > low, got {self.value_range!r}."
                )
            object.__setattr__(self, "value_range", (lo, hi))

    # -- evaluation -----------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.gaussians)

    def components(self, s: np.ndarray) -> np.ndarray:
        """Per-Gaussian opacity density at ``s``: shape (N, len(s))."""
        s = np.asarray(s, dtype=np.float64)
        means = np.array([g.mean for g in self.gaussians])[:, None]
        widths = np.array([g.width for g in self.gaussians])[:, None]
        heights = np.array([g.height for g in self.gaussians])[:, None]
        return heights * np.exp(-0.5 * ((s[None, :] - means) / widths) ** 2)

    def opacity(self, s: np.ndarray) -> np.ndarray:
        """Opacity per unit length at ``s``: the sum of the Gaussians, clamped to [0, 1]."""
        return np.clip(self.components(s).sum(axis=0), 0.0, 1.0)

    def color(self, s: np.ndarray) -> np.ndarray:
        """RGB at ``s``: the Gaussians' colours weighted by their contribution there.

        Where every contribution underflows, the colour of the Gaussian nearest in
        standardised distance is used (the value is invisible there anyway, but stays
        well defined and continuous in look).
        """
        s = np.asarray(s, dtype=np.float64)
        comps = self.components(s)  # (N, S)
        colors = np.array([g.color for g in self.gaussians])  # (N, 3)
        total = comps.sum(axis=0)
        rgb = np.empty((s.size, 3))
        ok = total > 1e-12
        rgb[ok] = (comps[:, ok].T @ colors) / total[ok, None]
        if not ok.all():
            means = np.array([g.mean for g in self.gaussians])[:, None]
            widths = np.array([g.width for g in self.gaussians])[:, None]
            nearest = np.argmin(np.abs(s[None, ~ok] - means) / widths, axis=0)
            rgb[~ok] = colors[nearest]
        return np.clip(rgb, 0.0, 1.0)

    def lut(self, size: int = 256, sample_distance: float = 1.0) -> np.ndarray:
        """RGBA lookup table, shape (size, 4) float32; entry k is value k / (size - 1).

        RGB is straight (not premultiplied). Alpha is the opacity of one sample taken every
        ``sample_distance`` unit lengths: ``1 - (1 - opacity) ** sample_distance``.
        """
        if not 2 <= int(size) <= 65536:
            raise TransferFunctionError(f"LUT size must be within [2, 65536], got {size}.")
        if not (math.isfinite(sample_distance) and sample_distance > 0):
            raise TransferFunctionError(
                f"The sample distance must be a positive number of voxels, got {sample_distance}."
            )
        s = np.linspace(0.0, 1.0, int(size))
        out = np.empty((int(size), 4), dtype=np.float32)
        out[:, :3] = self.color(s)
        a = self.opacity(s)
        if sample_distance != 1.0:
            a = 1.0 - np.power(1.0 - a, float(sample_distance))
        out[:, 3] = a
        return out

    # -- editing --------------------------------------------------------------------------
    def with_gaussians(self, gaussians: Iterable[Gaussian]) -> GaussianTF:
        return replace(self, gaussians=tuple(gaussians))

    def sorted(self) -> GaussianTF:
        """The same TF with Gaussians ordered by mean (a canonical form)."""
        return self.with_gaussians(sorted(self.gaussians, key=lambda g: g.mean))

    def frozen_mask(self) -> np.ndarray:
        return np.array([g.frozen for g in self.gaussians], dtype=bool)

    def freeze(self, keep_free: Sequence[int]) -> GaussianTF:
        """Freeze every Gaussian except those at the indices ``keep_free``."""
        free = set(int(i) for i in keep_free)
        return self.with_gaussians(
            replace(g, frozen=i not in free) for i, g in enumerate(self.gaussians)
        )

    def unfreeze(self) -> GaussianTF:
        return self.with_gaussians(replace(g, frozen=False) for g in self.gaussians)

    def hide(self, indices: Sequence[int]) -> GaussianTF:
        """The same TF with the Gaussians at ``indices`` at height 0 (the rest keep their
        indices; indices outside the TF are ignored)."""
        chosen = set(int(i) for i in indices)
        return self.with_gaussians(
            replace(g, height=0.0) if i in chosen else g for i, g in enumerate(self.gaussians)
        )

    def only(self, index: int) -> GaussianTF:
        """A TF with the single Gaussian ``index`` (for feature views)."""
        return self.with_gaussians([self.gaussians[index]])

    # -- serialisation --------------------------------------------------------------------
    def to_dict(self) -> dict:
        d: dict = {
            "format": TF_FORMAT,
            "version": TF_VERSION,
            "name": self.name,
            "gaussians": [g.to_dict() for g in self.gaussians],
        }
        if self.value_range is not None:
            d["value_range"] = list(self.value_range)
        if self.metadata:
            d["metadata"] = self.metadata
        return d

    @classmethod
    def from_dict(cls, d: dict) -> GaussianTF:
        if not isinstance(d, dict) or d.get("format") != TF_FORMAT:
            raise TransferFunctionError(
                'This is not an intuitf transfer function (missing "format": "intuitf.gaussian-tf").',
                "Use a TF JSON written by intuitf (optimize, export or the web app).",
            )
        try:
            version = int(d.get("version", 0))
        except (TypeError, ValueError) as exc:
            raise TransferFunctionError(
                f'The transfer function\'s "version" must be a whole number, got {d.get("version")!r}.'
            ) from exc
        if version > TF_VERSION:
            raise TransferFunctionError(
                f"This transfer function has format version {d.get('version')}, newer than this "
                f"intuitf understands ({TF_VERSION}).",
                "Upgrade intuitf.",
            )
        gs = d.get("gaussians")
        if not isinstance(gs, list):
            raise TransferFunctionError('A transfer function needs a list of "gaussians".')
        vr = d.get("value_range")
        return cls(
            gaussians=tuple(Gaussian.from_dict(g) for g in gs),
            # Anything but a list is passed on as is, for __post_init__ to reject clearly.
            value_range=tuple(vr) if isinstance(vr, list | tuple) else vr,
            name=str(d.get("name", "")),
            metadata=dict(md) if isinstance(md := d.get("metadata"), dict) else {},
        )

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent)

    @classmethod
    def from_json(cls, text: str) -> GaussianTF:
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise TransferFunctionError(f"The transfer function is not valid JSON: {exc}.") from exc
        return cls.from_dict(d)
