"""Real volumes from the shared data folder (INTUITF_DATA): values and figures from MANIFEST.md."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.volume import load_volume


@pytest.mark.parametrize(
    ("file", "dims", "dtype", "vmax", "mean", "lut"),
    [
        ("foot_zfp8lossy_256x256x256_uint8.raw.gz", (256, 256, 256), "uint8", 255, 13.94, 256),
        ("tooth_103x94x161_uint8.raw.gz", (103, 94, 161), "uint8", 255, 103.2, 256),
        ("ctheadstanford_256x256x113_uint16.raw.gz", (256, 256, 113), "uint16", 3272, 379.5, 3273),
        ("headsq_64x64x93_int16.raw.gz", (64, 64, 93), "int16", 3926, 507.7, 3927),
        ("hydrogenorbital3d_64x64x64_float32.raw.gz", (64, 64, 64), "float32", 1.0, 0.0185, 4096),
    ],
)
def test_real_volume(data_dir, file, dims, dtype, vmax, mean, lut):
    v = load_volume(data_dir / file)
    assert v.dims == dims
    assert v.original_dtype == dtype
    assert v.value_range[0] == pytest.approx(0.0, abs=1e-6)
    assert v.value_range[1] == pytest.approx(vmax, rel=1e-4)
    assert v.summary()["mean"] == pytest.approx(mean, rel=0.01)
    assert v.lut_size == lut
    assert v.name == file.split("_")[0]


def test_real_volume_orientation_tooth(data_dir):
    """The tooth's long axis (crown to root) runs along z, its largest dimension."""
    v = load_volume(data_dir / "tooth_103x94x161_uint8.raw.gz")
    fg = v.data > 0.3
    zs, ys, xs = np.nonzero(fg)
    assert np.ptp(zs) > np.ptp(ys) and np.ptp(zs) > np.ptp(xs)


def test_real_volume_downsampled(data_dir):
    v = load_volume(data_dir / "ctheadstanford_256x256x113_uint16.raw.gz",
                    spacing=(1, 1, 2), max_dim=64)  # fmt: skip
    assert v.dims == (64, 64, 28)
    assert v.extent == pytest.approx((255.0, 255.0, 224.0))
    assert v.value_range == (0.0, 3272.0)
    assert v.summary()["mean"] == pytest.approx(379.5, rel=0.05)
