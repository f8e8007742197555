"""Interactive views of a transfer function: picture, pick, feature decomposition, attribution.

These run with their own camera and size, apart from the judging camera, so looking at a
result never changes what the tournament sees. The :class:`ViewRenderer` keeps one renderer per
(size, shading) and the sample cache of the last camera it was asked about, so a click and
the decomposition that follows it share one pass through the volume. Its renderers take the
volume's gradient and block ranges from the volume's render context, so a view size costs only
its pictures.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from intuitf.errors import RenderError
from intuitf.tf import GaussianTF

if TYPE_CHECKING:
    from intuitf.render.cache import CacheViews
    from intuitf.render.camera import Camera
    from intuitf.render.renderer import VolumeRenderer
    from intuitf.volume import Volume

#: A feature counts as visible at a pixel when it holds at least this share of its opacity.
VISIBLE_SHARE = 0.02
#: ... and as under the cursor, for a pick, when it holds at least this part of the opacity
#: the pixel has: a speck that tints a pixel a little (a few pixels of bright noise in front
#: of a pot) would otherwise always be the smallest feature there and take every click.
PICK_SHARE = 0.15


@dataclass(frozen=True)
class PickResult:
    """The feature chosen at a pixel by the paper's rule, and what was there to choose from.

    ``index`` is the Gaussian with the smallest projected area among those visible at the
    pixel (None on empty background); ``visible`` lists (index, share at the pixel, area in
    pixels) for every visible Gaussian; ``selected`` is what the click selects: ``(index,)``
    for the paper's pick, every feature that makes the pixel for a whole pick
    (:func:`pick_whole`); ``mask`` marks the selected features' pixels.
    """

    index: int | None
    visible: tuple[tuple[int, float, int], ...]
    mask: np.ndarray | None
    selected: tuple[int, ...] = ()


class ViewRenderer:
    """Renders of one volume for interaction, cached per size, shading and camera.

    ``device`` None renders on the volume's device (its render context's).
    """

    def __init__(
        self,
        volume: Volume,
        background: Sequence[float] = (0.0, 0.0, 0.0),
        device: str | None = None,
    ) -> None:
        self.volume = volume
        self.background = tuple(background)
        self.device = device
        self._renderers: dict[tuple[int, bool], VolumeRenderer] = {}
        self._cache_key: tuple[str, int, bool] | None = None
        self._cache: CacheViews | None = None
        self._lock = threading.Lock()

    def renderer(self, size: int, shading: bool) -> VolumeRenderer:
        from intuitf.render import VolumeRenderer

        with self._lock:
            r = self._renderers.get((size, shading))
            if r is None:
                r = VolumeRenderer(
                    self.volume,
                    size=size,
                    shading=shading,
                    background=self.background,
                    device=self.device,
                )
                self._renderers[(size, shading)] = r
            return r

    def sample_cache(self, camera: Camera, size: int, shading: bool) -> CacheViews:
        key = (repr(camera.to_dict()), size, shading)
        with self._lock:
            if self._cache_key == key and self._cache is not None:
                return self._cache
        cache = self.renderer(size, shading).sample_cache(camera)
        with self._lock:
            self._cache_key, self._cache = key, cache
        return cache

    # -- the views ------------------------------------------------------------------------
    def view(self, tf: GaussianTF, camera: Camera, size: int, shading: bool) -> np.ndarray:
        """uint8 RGB (size, size, 3) of ``tf`` from ``camera``."""
        return self.renderer(size, shading).render(tf, camera)

    def attribution(self, tf: GaussianTF, camera: Camera, size: int, shading: bool) -> np.ndarray:
        """Each Gaussian's share of each pixel's opacity: float32 (N, size, size)."""
        return self.sample_cache(camera, size, shading).attribution(tf)

    def pick(
        self,
        tf: GaussianTF,
        camera: Camera,
        x: int,
        y: int,
        size: int,
        shading: bool,
        whole: bool = False,
    ) -> PickResult:
        """The feature under pixel (x, y): the smallest projected area among those that make
        the pixel (:func:`pick_smallest`); with ``whole``, all of them (:func:`pick_whole`)."""
        if not (0 <= x < size and 0 <= y < size):
            raise RenderError(
                f"Pixel ({x}, {y}) is outside the {size}×{size} view.",
                "Give x and y from the top-left corner, within the view's size.",
            )
        attribution = self.attribution(tf, camera, size, shading)
        return (pick_whole if whole else pick_smallest)(attribution, x, y)

    def features(
        self, tf: GaussianTF, camera: Camera, size: int, shading: bool
    ) -> list[np.ndarray]:
        """Each Gaussian rendered alone (over a faint ghost of the whole), in TF order."""
        cache = self.sample_cache(camera, size, shading)
        return [cache.render_feature(tf, i) for i in range(len(tf))]


def pick_bar(visible: Sequence[tuple[int, float, int]]) -> float:
    """The share a feature needs at a pixel to compete for a pick there: :data:`PICK_SHARE`
    of the pixel's opacity, or the largest share where no feature holds that much (where many
    features each make a little of the pixel, the largest still competes). ``visible``:
    (index, share, area) of the features visible at the pixel, at least one."""
    shares = [share for _, share, _ in visible]
    return min(PICK_SHARE * sum(shares), max(shares))


def pick_smallest(attribution: np.ndarray, x: int, y: int) -> PickResult:
    """The paper's rule over an attribution map (N, H, W): of the features under (x, y), the
    one whose projected area (pixels where it is visible) is smallest.

    Under the pixel means visible there (:data:`VISIBLE_SHARE`) and holding at least
    :data:`PICK_SHARE` of the pixel's opacity (or as much as any feature holds, where none
    holds that much); ``visible`` still lists every visible one.
    """
    visible_map, visible, making = _under(attribution, x, y)
    if not making:
        return PickResult(None, visible, None)
    chosen = making[0]
    return PickResult(chosen, visible, visible_map[chosen].copy(), (chosen,))


def pick_whole(attribution: np.ndarray, x: int, y: int) -> PickResult:
    """Every feature that makes pixel (x, y) (those :func:`pick_smallest` chooses among):
    the whole of what is seen there, where one structure is drawn by several Gaussians (a
    pot by a dense core and its rim). ``index`` is still the paper's choice; ``selected``
    lists them all in TF order and ``mask`` is their pixels together."""
    visible_map, visible, making = _under(attribution, x, y)
    if not making:
        return PickResult(None, visible, None)
    selected = tuple(sorted(making))
    mask = np.any(visible_map[list(selected)], axis=0)
    return PickResult(making[0], visible, np.asarray(mask, bool), selected)


def _under(
    attribution: np.ndarray, x: int, y: int
) -> tuple[np.ndarray, tuple[tuple[int, float, int], ...], list[int]]:
    """The visibility map, the features visible at (x, y) as (index, share, area), smallest
    area first, and those of them that make the pixel (above :func:`pick_bar`), in that order."""
    visible_map = attribution >= VISIBLE_SHARE
    areas = visible_map.reshape(len(attribution), -1).sum(axis=1)
    here = [int(i) for i in np.flatnonzero(visible_map[:, y, x])]
    visible = tuple(
        sorted(
            ((i, float(attribution[i, y, x]), int(areas[i])) for i in here),
            key=lambda t: (t[2], -t[1], t[0]),
        )
    )
    if not visible:
        return visible_map, (), []
    bar = pick_bar(visible)
    return visible_map, visible, [i for i, share, _ in visible if share >= bar]
