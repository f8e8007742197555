"""Hand-made transfer functions the tests render."""

from __future__ import annotations

import numpy as np

from intuitf.tf import Gaussian, GaussianTF


def tooth_tf() -> GaussianTF:
    """Dentin (orange, semi-transparent) and enamel (white, dense) of the tooth."""
    return GaussianTF(
        (
            Gaussian(mean=0.62, width=0.05, height=0.08, color=(0.9, 0.5, 0.3)),
            Gaussian(mean=0.92, width=0.04, height=0.6, color=(1.0, 1.0, 0.9)),
        )
    )


def random_tf(rng: np.random.Generator, n: int = 3) -> GaussianTF:
    """A candidate like the Explorer's: random means, widths, heights and colours."""
    return GaussianTF(
        tuple(
            Gaussian(
                mean=float(rng.uniform(0.1, 1.0)),
                width=float(rng.uniform(0.01, 0.12)),
                height=float(rng.uniform(0.005, 0.8)),
                color=tuple(float(c) for c in rng.uniform(0.0, 1.0, 3)),
            )
            for _ in range(n)
        )
    )


def target_tf() -> GaussianTF:
    """Three materials (faint skin, red tissue, dense bone): the explorer tests' hidden target."""
    return GaussianTF(
        (
            Gaussian(0.22, 0.03, 0.04, (0.9, 0.6, 0.5)),
            Gaussian(0.45, 0.02, 0.25, (0.8, 0.2, 0.2)),
            Gaussian(0.78, 0.04, 0.6, (0.95, 0.95, 0.85)),
        )
    )
