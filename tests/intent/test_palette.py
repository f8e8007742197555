"""Colours an intent asks for: reference pictures, sketches and colour words."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.evaluator.types import Intent
from intuitf.intent.palette import (
    intent_palette,
    palette_from_image,
    palette_from_sketch,
    palette_from_text,
)


def _close(a, b, tol=0.08) -> bool:
    return max(abs(x - y) for x, y in zip(a, b, strict=True)) <= tol


def _rendering_like() -> np.ndarray:
    """Orange (bright and faint, as opacity varies) over blue, on black."""
    img = np.zeros((64, 64, 3), np.float32)
    orange, blue = np.array([0.95, 0.55, 0.15]), np.array([0.35, 0.6, 0.95])
    img[8:30, 8:56] = orange * np.linspace(0.3, 1.0, 48)[None, :, None]  # faint to opaque
    img[34:60, 8:56] = blue * 0.6
    return (img * 255).round().astype(np.uint8)


def test_image_palette_recovers_colours_whatever_their_opacity():
    pal = palette_from_image(_rendering_like())
    assert 2 <= len(pal) <= 3
    assert any(_close(c, (0.95, 0.55, 0.15)) for c in pal)
    assert any(_close(c, (0.35, 0.6, 0.95)) for c in pal)
    # The background is not a colour of the picture.
    assert not any(max(c) < 0.2 for c in pal)
    assert palette_from_image(_rendering_like()) == pal  # deterministic


def test_image_palette_of_an_empty_picture_is_empty_and_bad_shapes_are_refused():
    assert palette_from_image(np.zeros((32, 32, 3), np.uint8)) == []
    white = np.full((32, 32, 3), 255, np.uint8)
    assert palette_from_image(white, background=(1.0, 1.0, 1.0)) == []
    with pytest.raises(ValueError, match="RGB"):
        palette_from_image(np.zeros((32, 32), np.uint8))


def test_sketch_palette_uses_only_the_strokes():
    sk = np.zeros((40, 40, 4), np.uint8)
    sk[..., :3] = 255  # white under transparent pixels must not count
    sk[5:15, 5:35] = (220, 30, 30, 255)
    sk[25:30, 5:35] = (40, 80, 220, 255)
    pal = palette_from_sketch(sk)
    assert len(pal) == 2
    assert _close(pal[0], (220 / 255, 30 / 255, 30 / 255), 0.02)  # the most used first
    assert _close(pal[1], (40 / 255, 80 / 255, 220 / 255), 0.02)
    assert palette_from_sketch(np.zeros((40, 40, 3), np.uint8)) == []


def test_text_palette_names_colours_in_order():
    pal = palette_from_text("opaque ivory bone, faint red skin")
    assert len(pal) == 2
    assert pal[0][0] > 0.9 and pal[0][2] > 0.8  # ivory
    assert pal[1][0] > 0.8 and pal[1][1] < 0.2  # red
    assert palette_from_text("show the bone") == []


def test_intent_palette_dispatches_on_the_kind():
    assert intent_palette(Intent()) == []
    assert len(intent_palette(Intent(kind="text", text="blue vessels"))) == 1
    assert len(intent_palette(Intent(kind="image", reference=_rendering_like()))) >= 2
