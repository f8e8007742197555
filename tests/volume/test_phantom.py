"""The built-in phantom: deterministic, CT-like, with distinct materials."""

from __future__ import annotations

import numpy as np

from intuitf.tf import find_materials
from intuitf.volume import load_volume, phantom
from intuitf.volume.phantom import MATERIALS


def test_phantom_is_deterministic_and_uint8():
    a, b = phantom(48, seed=3), phantom(48, seed=3)
    assert a.name == "phantom" and a.original_dtype == "uint8" and a.lut_size == 256
    assert a.shape == (48, 48, 48)
    np.testing.assert_array_equal(a.data, b.data)
    assert not np.array_equal(a.data, phantom(48, seed=4).data)


def test_phantom_has_distinct_materials():
    v = phantom()
    counts, _ = v.histogram(256)
    values = v.to_original(v.data)
    # Air around the head, and substantial soft tissue, bone and enamel.
    assert (values < 20).mean() > 0.3
    assert ((values > 90) & (values < 120)).mean() > 0.05
    assert ((values > 185) & (values < 225)).mean() > 0.005
    assert (values > 230).sum() > 50
    centres = [v.to_original(m.center) for m in find_materials(counts)]
    assert any(abs(c - MATERIALS["soft tissue"]) < 15 for c in centres)
    assert any(abs(c - MATERIALS["bone"]) < 20 for c in centres)


def test_phantom_is_not_symmetric_front_to_back():
    v = phantom(64)
    # The face (nose, jaw, teeth) is at +y; the back of the head is plain.
    assert not np.allclose(v.data, v.data[:, ::-1, :], atol=0.2)


def test_load_volume_builtin_names():
    assert load_volume("builtin:phantom").name == "phantom"
    v = load_volume("phantom", max_dim=32, name="ph")
    assert v.dims == (32, 32, 32) and v.name == "ph"
