"""Small volumes and a reference for the batch tests: phantoms at a few sizes and seeds saved as
.npy, real volumes (read downsampled with max_dim), and a TF with its picture."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from intuitf.imageio import save_png
from intuitf.render import VolumeRenderer
from intuitf.tf import save_tf
from intuitf.tf.defaults import default_tf
from intuitf.volume import load_volume
from intuitf.volume.phantom import phantom_array

_DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "volumes"

#: Search settings small enough for a test: a few seconds per volume.
TINY = dict(population=6, generations=2, image_size=32, output_size=48, top_k=1, seed=1,
            stages=[["customize", 2]])  # fmt: skip
TINY_ARGS = ["--population", "6", "--generations", "2", "--size", "32", "--output-size", "48",
             "--top", "1", "--seed", "1"]  # fmt: skip


@pytest.fixture(scope="session")
def tiny() -> dict:
    """The tiny search settings, as RunSpec settings and as command-line options."""
    return {"settings": dict(TINY), "args": list(TINY_ARGS)}


def data_dir() -> Path | None:
    d = Path(os.environ.get("INTUITF_DATA", _DATA)).resolve()
    return d if d.is_dir() else None


@pytest.fixture(scope="session")
def batch_inputs(tmp_path_factory) -> dict:
    """``vols/``: three phantoms (.npy) and, when the real data is there, one real volume;
    ``ref.tf.json`` + ``ref.png`` (rendered from ``ref.npy``, another phantom)."""
    root = tmp_path_factory.mktemp("batch-inputs")
    vols = root / "vols"
    vols.mkdir()
    for size, seed in ((32, 1), (36, 2), (40, 3)):
        np.save(vols / f"phantom{size}s{seed}.npy", phantom_array(size, seed))
    real = data_dir()
    if real is not None and (real / "nucleon_41x41x41_uint8.raw.gz").exists():
        (vols / "nucleon_41x41x41_uint8.raw.gz").symlink_to(real / "nucleon_41x41x41_uint8.raw.gz")
    np.save(root / "ref.npy", phantom_array(36, 0))
    ref_vol = load_volume(root / "ref.npy")
    tf = default_tf(ref_vol.histogram()[0], ref_vol.value_range)
    save_tf(tf, root / "ref.tf.json")
    save_png(VolumeRenderer(ref_vol, size=48).render(tf), root / "ref.png")
    return {"root": root, "vols": vols, "tf": root / "ref.tf.json", "ref_volume": root / "ref.npy",
            "picture": root / "ref.png"}  # fmt: skip


def target_picture(inputs: dict) -> np.ndarray:
    from intuitf.imageio import load_image

    return load_image(inputs["picture"])
