"""A cheap synthetic judge: ranks TFs by closeness of their LUTs to a hidden target."""

from __future__ import annotations

import numpy as np

from intuitf.tf import GaussianTF


def lut_distance(tf: GaussianTF, target_lut: np.ndarray) -> float:
    """Mean absolute difference of opacity and of opacity-weighted colour over a 64-entry LUT."""
    lut = tf.lut(64).astype(np.float64)
    a, at = lut[:, 3], target_lut[:, 3]
    col = np.abs(lut[:, :3] * a[:, None] - target_lut[:, :3] * at[:, None]).mean()
    return float(np.abs(a - at).mean() + col)


def rank_by_target(candidates, target_lut: np.ndarray) -> list[str]:
    """Candidate ids, closest to the target first."""
    d = [(lut_distance(c.tf, target_lut), c.id) for c in candidates]
    return [cid for _, cid in sorted(d)]
