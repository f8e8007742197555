"""A reference picture read as words: the colour at its outline and the colour inside it.

A rendering used as a reference (the paper's foot, given for a head or a chest) shows
layers: a faint outer material seen at the object's outline, and an opaque inner one seen
through it. Matching colours alone cannot tell which material of the new volume should get
which colour: a search that paints a head's skin opaque ivory matches the foot's colours and
hides its skull. So the picture is read as two layers (outline and inside) and turned into
words the structure map understands ("faint red outer part and opaque ivory inner part"),
with the picture's own colours: the first generation then places them on the new volume's
outer and inner structures, as a text would.

Algorithm code: no I/O; the picture is an array.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from skimage.color import deltaE_ciede2000, rgb2lab

from intuitf.intent.colours import colour_word

RGB = tuple[float, float, float]

#: Pixels this far (max channel, 0..1) from the background are the object.
_FOREGROUND = 0.04
#: The outline band is this share of the object's size (its bounding box's smaller side).
_BAND = 0.04
#: An outline this much darker (max channel) than the inside reads as faint.
_FAINT = 0.6
#: Layers closer than this (ΔE2000) are one colour: the picture says nothing about layers.
_SAME = 12.0
#: Value (max channel) both colours are scaled to: a shaded picture shows a material darker
#: than its colour (oblique surfaces get less light), by about as much as the palette's.
_VALUE = 0.95


def outline_and_inside(
    image: np.ndarray, background: RGB | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    """The colour (RGB, 0..1) of the object's outer layer, read at its outline, and of its
    inner one, read inside (each as lit and dimmed in the picture, but apart from the other);
    None without an object big enough to have both.

    The object is what differs from ``background`` (default: the median colour of the
    picture's border); the outline band is its pixels within a few per cent of its size of
    its edge, the inside what lies twice as deep. The outer colour is the mean of the band's
    dimmer half, the inner one the mean of the quarter of the inside's brighter half that the
    outer colour tints least: layers seen through each other mix (red skin over ivory bone
    shows pink), and the band's and the inside's plain means read such a foot as salmon over
    pinkish ivory.
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] < 3 or min(img.shape[:2]) < 8:
        return None
    rgb = img[..., :3].astype(np.float64)
    if img.dtype == np.uint8 or rgb.max() > 1.0:
        rgb = rgb / 255.0
    if background is None:
        border = np.concatenate([rgb[0], rgb[-1], rgb[:, 0], rgb[:, -1]])
        bg = np.median(border, axis=0)
    else:
        bg = np.asarray(background, np.float64)
    fg = np.abs(rgb - bg).max(axis=2) > _FOREGROUND
    fg = ndimage.binary_fill_holes(ndimage.binary_opening(fg, iterations=1))
    if fg.sum() < 64:
        return None
    rows, cols = np.nonzero(fg)
    size = min(rows.max() - rows.min(), cols.max() - cols.min()) + 1
    band = max(2, int(round(_BAND * size)))
    inner = ndimage.binary_erosion(fg, iterations=band)
    core = ndimage.binary_erosion(fg, iterations=2 * band)
    edge = fg & ~inner
    if edge.sum() < 16 or core.sum() < 16:
        return None
    value = np.abs(rgb - bg).max(axis=2)
    # The band's dimmer half: where the outer layer alone lies on the ray (a faint skin seen
    # edge-on); its brighter pixels are the inside showing through it.
    band = rgb[edge][value[edge] <= np.median(value[edge])]
    outline = band.mean(axis=0)
    inside = rgb[core][value[core] >= np.median(value[core])]
    # Of the inside, the quarter least tinted by the outline's colour: the inner material
    # where least of the outer layer lies in front of it.
    hue = outline - outline.mean()
    norm = float(np.linalg.norm(hue))
    if norm > 1e-6:
        tint = (inside - inside.mean(axis=1, keepdims=True)) @ (hue / norm)
        inside = inside[tint <= np.percentile(tint, 25)]
    return outline, inside.mean(axis=0)


def reference_layers(
    image: np.ndarray, background: RGB | None = None
) -> list[tuple[str, RGB, str | None]]:
    """The picture's layers: [("outer", rgb, look), ("inner", rgb, "opaque")] or [].

    From :func:`outline_and_inside`: over a dark background a faint outer material shows
    dimmed by its opacity, so it reads as "faint" when its outline is much darker than the
    inside. Both colours are then scaled to a value of 0.95, undoing the dimming and the
    shading's darkening. Empty when the picture has no object, or its outline and inside have
    the same colour (the picture says nothing about layers).
    """
    found = outline_and_inside(image, background)
    if found is None:
        return []
    outer_rgb, inner_rgb = found
    inner_v, outer_v = float(inner_rgb.max()), float(outer_rgb.max())
    if inner_v <= 0.05 or outer_v <= 0.02:
        return []
    outer_rgb = np.clip(outer_rgb * (_VALUE / outer_v), 0.0, 1.0)
    inner_rgb = np.clip(inner_rgb * (_VALUE / inner_v), 0.0, 1.0)
    labs = rgb2lab(np.stack([outer_rgb, inner_rgb])[None])[0]
    if float(deltaE_ciede2000(labs[:1], labs[1:])[0]) < _SAME:
        return []
    look = "faint" if outer_v < _FAINT * inner_v else None
    as_rgb = lambda c: (float(c[0]), float(c[1]), float(c[2]))  # noqa: E731
    return [("outer", as_rgb(outer_rgb), look), ("inner", as_rgb(inner_rgb), "opaque")]


def reference_words(layers: list[tuple[str, RGB, str | None]]) -> str:
    """The layers as words: "faint red outer part and opaque ivory inner part"."""
    parts = []
    for kind, rgb, look in layers:
        words = [look] if look else []
        words += [colour_word(np.asarray(rgb)), f"{kind} part"]
        parts.append(" ".join(words))
    return " and ".join(parts)
