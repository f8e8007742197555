"""Small synthetic volumes with named parts, for tests of structures and words."""

from __future__ import annotations

import numpy as np


def potted_tree(n: int = 48, seed: int = 0, soil: bool = False) -> np.ndarray:
    """A small synthetic bonsai, z up: a dense bowl at the bottom, a mid-density trunk rising
    from it, low-density leaves scattered at the top, noisy air around. With ``soil``, the bowl
    is filled with the trunk's material (one connected piece with it, as in the real scan)."""
    rng = np.random.default_rng(seed)
    z, y, x = np.mgrid[0:n, 0:n, 0:n].astype(np.float32)
    c = (n - 1) / 2.0
    r = np.sqrt((x - c) ** 2 + (y - c) ** 2)
    data = rng.normal(0.03, 0.01, (n, n, n)).astype(np.float32)
    bowl = (z >= 2) & (z <= 12) & (r <= 18) & ((r >= 15) | (z <= 4))
    data[bowl] = 0.85
    trunk = (z > 4) & (z < 38) & (np.sqrt((x - c) ** 2 + (y - c) ** 2) <= 2.0)
    data[trunk] = 0.5
    if soil:
        data[(z > 4) & (z <= 10) & (r < 15)] = 0.5
    for _ in range(120):
        pz, py, px = rng.integers(28, n - 3), rng.integers(6, n - 6), rng.integers(6, n - 6)
        data[pz : pz + 2, py : py + 2, px : px + 2] = 0.2
    return np.clip(data, 0, 1)
