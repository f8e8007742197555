"""Shared fixtures for the renderer tests: real volumes, read once per session."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from intuitf.tf import Gaussian, GaussianTF
from intuitf.volume import Volume, load_volume

DATA = Path(
    os.environ.get(
        "INTUITF_DATA", Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "volumes"
    )
)


def data_file(name: str) -> Path:
    p = DATA / name
    if not p.exists():
        pytest.skip(f"test volume {name} not found in {DATA} (set INTUITF_DATA)")
    return p


@pytest.fixture(scope="session")
def tooth() -> Volume:
    """CT tooth, 103×94×161 uint8, halved to about 52×47×81 to keep the tests fast."""
    return load_volume(data_file("tooth_103x94x161_uint8.raw.gz"), max_dim=80)


@pytest.fixture(scope="session")
def foot() -> Volume:
    """CT foot downsampled to 64³."""
    return load_volume(data_file("foot_zfp8lossy_256x256x256_uint8.raw.gz"), max_dim=64)


@pytest.fixture(scope="session")
def neghip() -> Volume:
    return load_volume(data_file("neghip_64x64x64_uint8.raw.gz"))


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
