"""Fixtures for the tests of intuitf.testing (the fake model server)."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.testing import images


@pytest.fixture(scope="session")
def oracle_images() -> tuple[np.ndarray, list[np.ndarray]]:
    return images.oracle_images()
