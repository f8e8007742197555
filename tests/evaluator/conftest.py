"""Shared fixtures for evaluator tests.

``oracle_images``: a hidden target image and candidates at increasing distance from it, so the
fake model server's preferences are known in advance (candidates[i] beats candidates[j] if i < j).
"""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.testing import images


@pytest.fixture(scope="session")
def oracle_images() -> tuple[np.ndarray, list[np.ndarray]]:
    return images.oracle_images()
