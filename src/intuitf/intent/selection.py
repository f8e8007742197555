"""Where the selected features of an edit are: a pixel mask of the rendering before the edit.

A click-and-say request ("make this gold") applies to the Gaussians the user selected. A judge
never sees a transfer function, so the Session gives it the pixels those Gaussians cover in the
rendering before the edit (:func:`selection_mask`, from the renderer's per-Gaussian attribution),
and a model judge is shown that rendering with the selection outlined (:func:`outline_selection`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import ndimage

#: A pixel belongs to the selection when the selected Gaussians give it at least this opacity...
_MIN_ALPHA = 0.06
#: ...and at least this share of everything the pixel shows.
_MIN_SHARE = 0.3


def selection_mask(
    attribution: np.ndarray,
    selected: Sequence[int],
    min_alpha: float = _MIN_ALPHA,
    min_share: float = _MIN_SHARE,
) -> np.ndarray:
    """Pixels where the ``selected`` Gaussians show, from an attribution array (N, H, W).

    ``attribution`` is :meth:`intuitf.render.cache.SampleCache.attribution`: each Gaussian's
    part of every pixel's composited opacity. A pixel is selected when the selected Gaussians
    contribute at least ``min_alpha`` of opacity there and at least ``min_share`` of the
    pixel's total; isolated specks are removed and small holes closed. Returns bool (H, W).
    """
    attr = np.asarray(attribution, dtype=np.float32)
    if attr.ndim != 3:
        raise ValueError(f"attribution must be (N, H, W), got shape {attr.shape}.")
    idx = sorted({int(i) for i in selected})
    if not idx or idx[0] < 0 or idx[-1] >= attr.shape[0]:
        raise ValueError(f"selected indices {idx} out of range for {attr.shape[0]} Gaussians.")
    sel = attr[idx].sum(axis=0)
    total = attr.sum(axis=0)
    mask = (sel >= min_alpha) & (sel >= min_share * np.maximum(total, 1e-6))
    if mask.any():
        mask = ndimage.binary_opening(mask, iterations=1) | ((sel >= 4 * min_alpha) & mask)
        mask = ndimage.binary_closing(mask, iterations=1, border_value=0)
    return mask


def outline_selection(
    base: np.ndarray,
    mask: np.ndarray,
    colour: tuple[int, int, int] = (255, 0, 255),
    dim: float = 0.45,
) -> np.ndarray:
    """``base`` (uint8 RGB) with the selection outlined in ``colour`` and the rest dimmed.

    The outline is two pixels wide, drawn just outside the selected region; pixels outside
    it keep ``1 - dim`` of their brightness, so the selection stands out without hiding the
    context. A mask of another size than ``base`` is resized (nearest neighbour).
    """
    img = np.asarray(base)[..., :3].astype(np.float32)
    m = _fit_mask(mask, img.shape[:2])
    out = img.copy()
    out[~m] *= 1.0 - dim
    ring = ndimage.binary_dilation(m, iterations=2) & ~m
    out[ring] = colour
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def _fit_mask(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    m = np.asarray(mask).astype(bool)
    if m.shape == shape:
        return m
    rows = (np.arange(shape[0]) * m.shape[0] // shape[0]).clip(0, m.shape[0] - 1)
    cols = (np.arange(shape[1]) * m.shape[1] // shape[1]).clip(0, m.shape[1] - 1)
    return m[rows][:, cols]


def edit_intent(intent, volume, tf, settings):
    """``intent`` (an edit of ``tf``'s selected Gaussians) with its base picture, mask and
    the picture behind the selection.

    For the Session: the rendering before the edit (when the intent has none), made as the
    candidates are (the same sample cache, so an unchanged TF gives the same pixels), the
    pixels the selected Gaussians cover in it (:func:`selection_mask`) and ``tf`` rendered
    with them hidden (``Intent.behind``: where "transparent" goes; a pot made transparent
    shows the soil in it, which can stand out more from the background than the pot did).
    ``settings`` gives the camera, picture size, shading and background (a ``RunSettings``).
    """
    from dataclasses import replace

    from intuitf.render import Camera, VolumeRenderer

    wants_behind = intent.behind is None and bool(intent.selected)
    if intent.base is not None and intent.selection_mask is not None and not wants_behind:
        return intent
    camera = Camera.from_dict(settings.camera) if settings.camera else Camera()
    cache = VolumeRenderer(
        volume,
        size=settings.image_size,
        shading=settings.shading,
        background=tuple(settings.background),
    ).sample_cache(camera)
    made = cache.render(tf)
    base = intent.base if intent.base is not None else made
    mask = intent.selection_mask
    if mask is None and intent.selected:
        mask = selection_mask(cache.attribution(tf), intent.selected)
    behind = intent.behind
    # Only behind this view's own picture (a resumed run's base, read back, is that picture;
    # one given from another view is not).
    if wants_behind and np.shape(base) == made.shape and np.array_equal(base, made):
        behind = cache.render(tf.hide(intent.selected))
    return replace(intent, base=base, selection_mask=mask, behind=behind)
