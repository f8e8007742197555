"""The pre-integrated table against integrals worked out independently (fine trapezoids)."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.tf import Gaussian, GaussianTF
from intuitf.tf.preintegration import TABLE_SIZE, preintegrated_table

TWO = GaussianTF(
    (
        Gaussian(mean=0.4, width=0.003, height=0.6, color=(0.1, 0.3, 1.0)),
        Gaussian(mean=0.7, width=0.05, height=0.3, color=(1.0, 0.8, 0.2)),
    )
)


def _segment(tf: GaussianTF, f: float, b: float, d: float) -> tuple[float, np.ndarray]:
    """Alpha and straight colour of the segment f -> b, from 20,001 trapezoids."""
    s = np.linspace(min(f, b), max(f, b), 20001)
    tau = -np.log1p(-np.minimum(tf.opacity(s), 1 - 1e-6))
    mean_tau = np.trapezoid(tau, s) / (s[-1] - s[0])
    colour = np.trapezoid(tf.color(s) * tau[:, None], s, axis=0) / np.trapezoid(tau, s)
    return float(-np.expm1(-d * mean_tau)), colour


def test_the_diagonal_is_the_lut_and_the_table_is_symmetric():
    for d in (0.5, 1.0):
        table = preintegrated_table(TWO, d)
        lut = TWO.lut(TABLE_SIZE, d)
        diag = table[np.arange(TABLE_SIZE), np.arange(TABLE_SIZE)]
        np.testing.assert_allclose(diag[:, 3], lut[:, 3], atol=2e-6)
        shows = lut[:, 3] > 1e-4
        np.testing.assert_allclose(diag[shows, :3], lut[shows, :3], atol=1e-5)
        np.testing.assert_array_equal(table, table.transpose(1, 0, 2))


@pytest.mark.parametrize("f, b", [(100, 110), (95, 130), (150, 200), (60, 240)])
def test_a_segment_holds_what_the_tf_does_between_its_two_values(f, b):
    """Among them segments across the thin Gaussian at 0.4 (entry 102), which neither
    sample's value shows."""
    d = 0.5
    table = preintegrated_table(TWO, d)
    alpha, colour = _segment(TWO, f / 255, b / 255, d)
    assert table[f, b, 3] == pytest.approx(alpha, rel=2e-3, abs=1e-6)
    if alpha > 1e-4:
        np.testing.assert_allclose(table[f, b, :3], colour, atol=2e-3)
    premultiplied = preintegrated_table(TWO, d, premultiply=True)
    np.testing.assert_allclose(premultiplied[f, b, :3], table[f, b, :3] * table[f, b, 3], atol=1e-6)


def test_the_thin_gaussian_shows_only_in_segments_that_cross_it():
    table = preintegrated_table(TWO, 0.5, alpha_epsilon=1e-5)
    lut = TWO.lut(TABLE_SIZE, 0.5)
    # Entries 95 and 110 lie on either side of it: each sample alone shows nearly nothing,
    # the segment between them a good part of the shell's opacity.
    assert lut[95, 3] < 1e-3 and lut[110, 3] < 1e-3
    assert table[95, 110, 3] > 0.01
    # Below it, nothing at all: empty-space skipping relies on exact zeros.
    assert table[10, 60, 3] == 0.0 and table[60, 10, 3] == 0.0
