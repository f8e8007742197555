"""Fixtures every test folder shares; plain helpers are in the ``helpers`` package.

Real volumes come from ``$INTUITF_DATA`` (default ``../shared/data/volumes``); a test that needs
one skips when it is absent. Volumes are read once per test session.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers.data import DATA, data_file
from helpers.tfs import target_tf as _target_tf
from intuitf.tf import GaussianTF
from intuitf.volume import Volume, load_volume


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """Folder of real volumes (``INTUITF_DATA``); tests that need it skip when it is absent."""
    if not DATA.is_dir():
        pytest.skip(f"real volumes not found in {DATA} (set INTUITF_DATA)")
    return DATA


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


@pytest.fixture(scope="session")
def oracle_images() -> tuple[np.ndarray, list[np.ndarray]]:
    """A hidden target image and candidates at increasing distance from it, so the fake model
    server's preferences are known in advance (candidates[i] beats candidates[j] if i < j)."""
    from intuitf.testing import images

    return images.oracle_images()


@pytest.fixture
def target_tf() -> GaussianTF:
    """The explorer tests' hidden target TF (see :func:`helpers.tfs.target_tf`)."""
    return _target_tf()


@pytest.fixture(autouse=True, scope="session")
def _private_structure_cache(tmp_path_factory: pytest.TempPathFactory):
    """Structure maps (and the names a model gave them) are cached per volume on disk: the
    tests keep theirs in a folder of their own, so no test finds another run's names."""
    import os

    old = os.environ.get("INTUITF_CACHE_DIR")
    os.environ["INTUITF_CACHE_DIR"] = str(tmp_path_factory.mktemp("intuitf-cache"))
    yield
    if old is None:
        os.environ.pop("INTUITF_CACHE_DIR", None)
    else:
        os.environ["INTUITF_CACHE_DIR"] = old
