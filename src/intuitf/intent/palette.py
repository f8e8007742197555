"""The colours an intent asks for: a palette the Explorer can draw new colours from.

A reference picture's dominant colours, the colours of a sketch's strokes, or the colour
words of a text. The Explorer never sees images; it gets this list of RGB colours, like it
gets the volume's histogram, and uses it as a hint (new colours come from it part of the
time, the rest from the whole colour space, so a poor hint cannot trap the search).
"""

from __future__ import annotations

import numpy as np
from scipy.cluster.vq import kmeans2

from intuitf.evaluator.types import Intent
from intuitf.intent.colours import NAMED_COLOURS, named_colours

RGB = tuple[float, float, float]

#: Pixels this far (max channel, 0..1) from the background count as foreground.
_FOREGROUND = 0.04
#: Clusters holding less than this share of the (brightness-weighted) foreground are dropped.
_MIN_SHARE = 0.03
#: Colours closer than this (max channel) to one already in the palette are merged into it.
_DISTINCT = 0.08
#: Value (max channel) the palette colours are scaled to; see :func:`palette_from_image`.
_VALUE = 0.95


def _dominant(
    colours: np.ndarray, weights: np.ndarray | None, k: int, seed: int
) -> list[tuple[np.ndarray, float]]:
    """k-means over ``colours`` (N x 3, sampled by ``weights``): (centre, share), largest first.

    Clusters under ``_MIN_SHARE`` are dropped, and a centre within ``_DISTINCT`` of a larger
    one is merged into it.
    """
    rng = np.random.default_rng(seed)
    p = None if weights is None else weights / weights.sum()
    sample = colours[rng.choice(len(colours), size=min(4000, len(colours)), p=p)]
    k = max(1, min(int(k), len(np.unique(np.round(sample, 2), axis=0))))
    centres, labels = kmeans2(sample.astype(np.float64), k, seed=seed, minit="++")
    shares = np.bincount(labels, minlength=k) / len(labels)
    out: list[tuple[np.ndarray, float]] = []
    for i in np.argsort(-shares, kind="stable"):
        centre = np.clip(centres[i], 0.0, 1.0)
        if shares[i] >= _MIN_SHARE and all(np.abs(centre - c).max() > _DISTINCT for c, _ in out):
            out.append((centre, float(shares[i])))
    return out


def _rgb(c: np.ndarray) -> RGB:
    return (float(c[0]), float(c[1]), float(c[2]))


def palette_from_image(
    image: np.ndarray,
    k: int = 6,
    background: RGB = (0.0, 0.0, 0.0),
    seed: int = 0,
) -> list[RGB]:
    """Up to ``k`` dominant colours of a rendering-like picture, most prominent first.

    A volume rendering's pixel is a Gaussian's colour times the opacity gathered along the
    ray, so brightness says little about the colour a TF needs. Pixels are therefore
    compared by chromaticity (each scaled so its largest channel is 1), clustered with
    k-means (brighter pixels weigh more: they are the more opaque, less blended ones), and
    each cluster's colour is given at a fixed value of 0.95. Pixels at the ``background``
    colour (or transparent, for RGBA) are ignored. Deterministic for a given ``seed``.
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ValueError(f"Expected an RGB or RGBA image, got shape {img.shape}.")
    img = img.astype(np.float32) / 255.0 if img.dtype == np.uint8 else img.astype(np.float32)
    rgb = img[..., :3].reshape(-1, 3)
    bg = np.asarray(background, dtype=np.float32)
    fg = np.abs(rgb - bg).max(axis=1) > _FOREGROUND
    if img.shape[2] == 4:
        fg &= img[..., 3].reshape(-1) > 0.05
    rgb = rgb[fg & np.isfinite(rgb).all(axis=1)]
    if len(rgb) < 16:
        return []
    value = np.maximum(rgb.max(axis=1), 1e-6)
    chroma = np.clip(rgb / value[:, None], 0.0, 1.0)
    return [_rgb(c * _VALUE) for c, _ in _dominant(chroma, value, k, seed)]


def palette_from_sketch(sketch: np.ndarray, k: int = 6, seed: int = 0) -> list[RGB]:
    """The colours of a sketch's strokes (RGBA, alpha > 0 where drawn), most used first.

    A stroke's colour is meant literally (no opacity blending), so colours are clustered as
    drawn; every stroke pixel counts, however dark, since transparency marks what was not.
    """
    sk = np.asarray(sketch)
    if sk.ndim != 3 or sk.shape[2] != 4:
        return []
    drawn = sk[..., 3] > 0
    if drawn.sum() < 16:
        return []
    pix = sk[..., :3][drawn].astype(np.float32)
    pix = pix / 255.0 if sk.dtype == np.uint8 else pix
    return [_rgb(c) for c, _ in _dominant(pix, None, k, seed)]


def palette_from_text(text: str) -> list[RGB]:
    """The colours named in ``text`` ("ivory bone, faint red skin": ivory, red), in order."""
    return [_rgb(np.asarray(NAMED_COLOURS[name]) / 255.0) for name in named_colours(text or "")]


def intent_palette(intent: Intent, background: RGB = (0.0, 0.0, 0.0)) -> list[RGB]:
    """The palette an intent suggests (empty when it names no colours)."""
    if intent.kind == "image" and intent.reference is not None:
        return palette_from_image(intent.reference, background=background)
    if intent.kind == "sketch" and intent.sketch is not None:
        return palette_from_sketch(intent.sketch)
    if intent.text:
        return palette_from_text(intent.text)
    return []
