"""Carrying a TF to another volume: "bone" lands on bone when the scanner's values differ."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.batch.transfer import material_map, transfer_tf, unit_map
from intuitf.tf import Gaussian, GaussianTF
from intuitf.volume import Volume
from intuitf.volume.phantom import MATERIALS, phantom_array


def _volume(a: np.ndarray) -> Volume:
    return Volume.from_array(a, name="v")


def _scanner(v: np.ndarray) -> np.ndarray:
    """Another scanner: a non-linear response and another unit (12-bit, offset)."""
    return (1000 + 3000 * (v.astype(np.float64) / 255.0) ** 1.6).astype(np.uint16)


def _scan(v: np.ndarray) -> np.ndarray:
    """A scan by that scanner, with a few voxels of metal at the top of its range."""
    out = _scanner(v)
    out[0, 0, :4] = 4095
    return out


def _tf_on(vol: Volume, grey: dict[str, float]) -> GaussianTF:
    colours = {"soft tissue": (0.8, 0.3, 0.3), "bone": (0.95, 0.9, 0.75), "enamel": (1, 1, 1)}
    return GaussianTF(
        tuple(
            Gaussian(min(1.0, float(vol.to_normalised(grey[m]))), 0.02, h, colours[m])
            for m, h in (("soft tissue", 0.05), ("bone", 0.6), ("enamel", 0.9))
        ),
        value_range=vol.value_range,
    )


def test_bone_lands_on_bone_on_another_scanner():
    ref = _volume(phantom_array(48, 0))
    raw = phantom_array(40, 5)
    target = _volume(_scan(raw))
    tf = _tf_on(ref, MATERIALS)
    carried, vm = transfer_tf(
        tf,
        target.histogram()[0],
        ref_counts=ref.histogram()[0],
        ref_range=ref.value_range,
        target_range=target.value_range,
    )
    assert carried.value_range == target.value_range
    mapped = {
        m: float(target.to_normalised(_scanner(np.array([g]))[0])) for m, g in MATERIALS.items()
    }
    got = [g.mean for g in carried.gaussians]
    # Each material's Gaussian sits on that material in the new volume ...
    assert got[0] == pytest.approx(mapped["soft tissue"], abs=0.04)
    assert got[1] == pytest.approx(mapped["bone"], abs=0.04)
    # ... where copying the numbers would have missed it (and the heights and colours stay).
    assert abs(tf.gaussians[1].mean - mapped["bone"]) > 0.08
    assert [g.height for g in carried.gaussians] == [g.height for g in tf.gaussians]
    assert [g.color for g in carried.gaussians] == [g.color for g in tf.gaussians]
    assert len(vm.pairs) >= 2


def test_the_same_histogram_maps_values_to_themselves():
    counts = _volume(phantom_array(40, 1)).histogram()[0]
    vm = material_map(counts, counts)
    xs = np.linspace(0, 1, 11)
    np.testing.assert_allclose(vm(xs), xs, atol=1e-9)


def test_without_the_reference_volume_values_go_by_units():
    vm = unit_map((0.0, 255.0), (0.0, 510.0))
    assert vm(1.0) == pytest.approx(0.5)
    assert vm(0.5) == pytest.approx(0.25)
    assert unit_map(None, (0.0, 1.0))(0.3) == pytest.approx(0.3)
