"""PNG writing and picture reading."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.errors import IntuitfError
from intuitf.imageio import load_image, load_image_rgba, png_bytes, save_png


def test_png_round_trip_and_atomic_write(tmp_path):
    img = (np.arange(24 * 32 * 3) % 251).astype(np.uint8).reshape(24, 32, 3)
    p = save_png(img, tmp_path / "sub" / "a.png")
    np.testing.assert_array_equal(load_image(p), img)
    np.testing.assert_array_equal(load_image(png_bytes(img)), img)
    assert sorted(x.name for x in p.parent.iterdir()) == ["a.png"]  # no temp file left
    rgba = load_image_rgba(p)
    assert rgba.shape == (24, 32, 4) and (rgba[..., 3] == 255).all()


def test_transparent_pictures_flatten_onto_white(tmp_path):
    rgba = np.zeros((4, 4, 4), dtype=np.uint8)
    rgba[..., 0] = 255
    rgba[:2, :, 3] = 255  # top half opaque red, bottom transparent
    p = save_png(rgba, tmp_path / "t.png")
    rgb = load_image(p)
    np.testing.assert_array_equal(rgb[0, 0], [255, 0, 0])
    np.testing.assert_array_equal(rgb[3, 0], [255, 255, 255])


def test_unreadable_pictures_raise_one_clear_error(tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a picture")
    with pytest.raises(IntuitfError, match="cannot read"):
        load_image(bad)
    with pytest.raises(IntuitfError, match="no such"):
        load_image(tmp_path / "missing.png")
    with pytest.raises(IntuitfError):
        save_png(np.zeros((2, 2, 5)), tmp_path / "x.png")
