"""Shared fixtures for evaluator tests.

``oracle_images``: a hidden target image and candidates at increasing distance from it, so the
fake model server's preferences are known in advance (candidates[i] beats candidates[j] if i < j).
"""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="session")
def oracle_images() -> tuple[np.ndarray, list[np.ndarray]]:
    rng = np.random.default_rng(7)
    target = rng.integers(0, 256, (48, 48, 3), dtype=np.uint8)
    # Blend towards the inverted target: candidate k differs from the target by ~k * 20 grey levels.
    inverted = 255.0 - target.astype(np.float64)
    candidates = []
    for k in range(8):
        t = 0.08 * (k + 1)
        img = (1 - t) * target + t * inverted
        candidates.append(np.clip(img + 0.5, 0, 255).astype(np.uint8))
    return target, candidates
