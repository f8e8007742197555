"""Shared helpers: a cheap synthetic judge that ranks TFs by closeness to a hidden target."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.tf import Gaussian, GaussianTF


def lut_distance(tf: GaussianTF, target_lut: np.ndarray) -> float:
    """Mean absolute difference of opacity and of opacity-weighted colour over a 64-entry LUT."""
    lut = tf.lut(64).astype(np.float64)
    a, at = lut[:, 3], target_lut[:, 3]
    col = np.abs(lut[:, :3] * a[:, None] - target_lut[:, :3] * at[:, None]).mean()
    return float(np.abs(a - at).mean() + col)


def rank_by_target(candidates, target_lut: np.ndarray) -> list[str]:
    d = [(lut_distance(c.tf, target_lut), c.id) for c in candidates]
    return [cid for _, cid in sorted(d)]


@pytest.fixture
def target_tf() -> GaussianTF:
    return GaussianTF(
        (
            Gaussian(0.22, 0.03, 0.04, (0.9, 0.6, 0.5)),
            Gaussian(0.45, 0.02, 0.25, (0.8, 0.2, 0.2)),
            Gaussian(0.78, 0.04, 0.6, (0.95, 0.95, 0.85)),
        )
    )
