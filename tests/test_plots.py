"""Plots: the pictures carry the TF's colours where they belong, at the requested sizes."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from intuitf.plots import contact_sheet, evolution_plot, tf_plot
from intuitf.tf import Gaussian, GaussianTF


def decode(png: bytes) -> np.ndarray:
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)


def reddish(img: np.ndarray) -> np.ndarray:
    return (img[..., 0] > 170) & (img[..., 1] < 70) & (img[..., 2] < 70)


def blueish(img: np.ndarray) -> np.ndarray:
    return (img[..., 2] > 170) & (img[..., 0] < 70) & (img[..., 1] < 70)


def test_tf_plot_size_and_colours_at_the_gaussians():
    tf = GaussianTF(
        (
            Gaussian(0.25, 0.03, 0.5, (0.9, 0.05, 0.05)),
            Gaussian(0.75, 0.03, 0.5, (0.05, 0.05, 0.9)),
        ),
        value_range=(0.0, 255.0),
    )
    img = decode(tf_plot(tf, size=(640, 240)))
    assert img.shape == (240, 640, 3)
    red_cols = np.flatnonzero(reddish(img).any(axis=0))
    blue_cols = np.flatnonzero(blueish(img).any(axis=0))
    assert len(red_cols) > 20 and len(blue_cols) > 20
    # Red is painted on the left part of the axis, blue on the right, never mixed up.
    assert red_cols.max() < 320 < blue_cols.min()


def test_tf_plot_draws_the_histogram_and_works_without_units():
    tf = GaussianTF((Gaussian(0.5, 0.05, 0.3, (0.9, 0.05, 0.05)),))
    counts = np.zeros(256)
    counts[20:60] = 1000  # a material away from the Gaussian
    plain = decode(tf_plot(tf, size=(500, 200)))
    with_hist = decode(tf_plot(tf, counts, size=(500, 200)))
    assert plain.shape == (200, 500, 3)

    def histogram_grey(img):
        return (np.abs(img - [217, 221, 227]).sum(axis=2) < 12).sum()

    assert histogram_grey(with_hist) > 500
    assert histogram_grey(with_hist) > 10 * histogram_grey(plain)  # not grid lines


def test_contact_sheet_layout_tiles_and_captions():
    colors = [(255, 0, 0), (0, 255, 0), (0, 0, 255), (255, 255, 0), (0, 255, 255)]
    images = [np.full((40, 40, 3), c, dtype=np.uint8) for c in colors]
    images[1] = np.full((20, 40, 3), 1.0)  # float, wide: scaled and centred, white
    sheet = contact_sheet(images, [f"#{i} c{i} 1500" for i in range(5)], columns=2, thumb=80)
    assert sheet.dtype == np.uint8
    pad, cap = 6, 14
    assert sheet.shape == (3 * (80 + cap + pad) + pad, 2 * (80 + pad) + pad, 3)
    # Centre of each tile has its image's colour.
    for i, c in enumerate(colors):
        r, col = divmod(i, 2)
        y, x = pad + r * (80 + cap + pad) + 40, pad + col * (80 + pad) + 40
        expected = (255, 255, 255) if i == 1 else c
        assert tuple(sheet[y, x]) == expected
    # The wide image leaves black bars above and below.
    assert tuple(sheet[pad + 2, pad + 80 + pad + 40]) == (0, 0, 0)
    # Captions: light text pixels under the first tile.
    caption = sheet[pad + 80 : pad + 80 + cap, pad : pad + 80]
    assert (caption.min(axis=2) > 150).sum() > 10
    # The empty sixth cell stays background.
    assert (sheet[-30:, -60:] == sheet[0, 0]).all()


def test_contact_sheet_rejects_mismatched_input():
    with pytest.raises(ValueError):
        contact_sheet([np.zeros((4, 4, 3))], ["a", "b"])
    with pytest.raises(ValueError):
        contact_sheet([], [])


def test_evolution_plot_draws_each_panel():
    recs = [
        {
            "generation": g,
            "best_rating": 1500 + 30 * g,
            "mean_rating": 1500 + 10 * g,
            "min_rating": 1500 - 10 * g,
            "calls": 20,
            "cost_usd": 0.01,
            "seconds": 5.0,
        }
        for g in range(6)
    ]
    img = decode(evolution_plot(recs))
    assert img.shape == (300, 960, 3)
    thirds = np.array_split(img, 3, axis=1)
    blue = (np.abs(thirds[0] - [31, 95, 191]).sum(axis=2) < 40).sum()  # best line
    green = (np.abs(thirds[1] - [42, 138, 87]).sum(axis=2) < 40).sum()  # calls line
    purple = (np.abs(thirds[2] - [125, 76, 179]).sum(axis=2) < 40).sum()  # time line
    assert blue > 100 and green > 100 and purple > 100
    # No records and a single record still make a picture.
    assert decode(evolution_plot([])).shape == (300, 960, 3)
    assert decode(evolution_plot(recs[:1])).shape == (300, 960, 3)
