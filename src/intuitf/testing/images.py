"""Pictures whose order a fake judge knows in advance, for tests of judges and servers."""

from __future__ import annotations

import numpy as np


def oracle_images(seed: int = 7, size: int = 48) -> tuple[np.ndarray, list[np.ndarray]]:
    """A random target picture and eight candidates at rising distance from it.

    Candidate ``k`` is the target blended ``0.08 (k + 1)`` of the way to its negative, so it
    differs by about ``20 k`` grey levels: an oracle prefers ``candidates[i]`` to
    ``candidates[j]`` whenever ``i < j``.
    """
    rng = np.random.default_rng(seed)
    target = rng.integers(0, 256, (size, size, 3), dtype=np.uint8)
    inverted = 255.0 - target.astype(np.float64)
    candidates = []
    for k in range(8):
        t = 0.08 * (k + 1)
        img = (1 - t) * target + t * inverted
        candidates.append(np.clip(img + 0.5, 0, 255).astype(np.uint8))
    return target, candidates


def red_disc(size: int = 64) -> np.ndarray:
    """A red disc on black (radius 18 of 64): the fake model server's usual target picture."""
    y, x = np.mgrid[0:size, 0:size] * (64.0 / size)
    img = np.zeros((size, size, 3), np.uint8)
    img[(x - 32) ** 2 + (y - 32) ** 2 < 18**2] = (200, 60, 40)
    return img
