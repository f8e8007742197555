"""Exports read back by independent parsers (and VTK itself) describe the same TF."""

from __future__ import annotations

import json
import runpy

import numpy as np
import pytest

from intuitf.errors import TransferFunctionError
from intuitf.tf import Gaussian, GaussianTF
from intuitf.tf.export import EXPORT_FORMATS, export_tf
from intuitf.tf.export_io import export_path, write_export

LO, HI = -1024.0, 3071.0
# Largest differences allowed between an export and the TF it came from.
OPACITY_ATOL = 0.005
COLOR_ATOL = 0.01


def ct_tf(**kw) -> GaussianTF:
    """Faint skin, a very narrow bright vessel, wide opaque bone that saturates."""
    args = dict(value_range=(LO, HI), name="ct test")
    args.update(kw)
    return GaussianTF(
        (
            Gaussian(mean=0.25, width=0.04, height=0.05, color=(0.9, 0.6, 0.5)),
            Gaussian(mean=0.5, width=0.002, height=0.9, color=(1.0, 0.1, 0.1)),
            Gaussian(mean=0.8, width=0.08, height=0.7, color=(1.0, 1.0, 0.9)),
            Gaussian(mean=0.85, width=0.05, height=0.6, color=(0.3, 0.3, 1.0)),
        ),
        **args,
    )


def probe_values(n: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    """Original-unit values (random plus dense around the narrow Gaussian) and their [0,1] values."""
    rng = np.random.default_rng(0)
    s = np.concatenate([rng.random(n), 0.5 + np.linspace(-0.01, 0.01, 201), [0.0, 1.0]])
    return LO + s * (HI - LO), s


def check_same_tf(tf, x, s, opacity, rgb, unit_scale=1.0):
    expected_a = tf.opacity(s)
    if unit_scale != 1.0:
        expected_a = 1 - (1 - expected_a) ** unit_scale
    np.testing.assert_allclose(opacity, expected_a, atol=OPACITY_ATOL)
    np.testing.assert_allclose(rgb, tf.color(s), atol=COLOR_ATOL)


# -- independent readers, written from the format descriptions --------------------------------
def read_paraview(text):
    preset = json.loads(text)[0]
    rgbp = np.array(preset["RGBPoints"], dtype=float).reshape(-1, 4)
    pts = np.array(preset["Points"], dtype=float).reshape(-1, 4)
    return preset, rgbp, pts


def read_vp(text):
    lines = text.splitlines()
    assert len(lines) == 9

    def nodes(line, width):
        vals = [float(v) for v in line.split()]
        count = int(vals[0])
        assert count == len(vals) - 1 and count % width == 0
        return np.array(vals[1:]).reshape(-1, width)

    return {
        "interpolation": int(lines[0]),
        "shade": int(lines[1]),
        "diffuse": float(lines[2]),
        "ambient": float(lines[3]),
        "specular": float(lines[4]),
        "specular_power": float(lines[5]),
        "opacity": nodes(lines[6], 2),
        "gradient": nodes(lines[7], 2),
        "color": nodes(lines[8], 4),
    }


def read_1dt(text):
    lines = text.strip().splitlines()
    n = int(lines[0])
    table = np.array([[float(v) for v in line.split()] for line in lines[1:]])
    assert table.shape == (n, 4)
    return table


# -- the formats ------------------------------------------------------------------------------
def test_paraview_preset_matches_tf_in_original_units():
    tf = ct_tf()
    preset, rgbp, pts = read_paraview(export_tf(tf, "paraview", unit_distance=0.7))
    assert preset["Name"] == "ct test" and preset["ColorSpace"] == "RGB"
    assert preset["ScalarOpacityUnitDistance"] == 0.7
    assert rgbp[0, 0] == LO and rgbp[-1, 0] == HI and pts[0, 0] == LO and pts[-1, 0] == HI
    assert np.all(np.diff(rgbp[:, 0]) > 0) and np.all(np.diff(pts[:, 0]) > 0)
    assert np.all(pts[:, 2] == 0.5) and np.all(pts[:, 3] == 0.0)
    x, s = probe_values()
    rgb = np.column_stack([np.interp(x, rgbp[:, 0], rgbp[:, c]) for c in (1, 2, 3)])
    check_same_tf(tf, x, s, np.interp(x, pts[:, 0], pts[:, 1]), rgb)
    # Simplification keeps the file small: far fewer points than the 4097 samples.
    assert len(pts) < 300 and len(rgbp) < 300


def test_slicer_vp_layout_and_values():
    tf = ct_tf()
    vp = read_vp(export_tf(tf, "slicer"))
    assert vp["interpolation"] == 1 and vp["shade"] == 1
    assert 0 <= vp["ambient"] <= 1 and 0 <= vp["diffuse"] <= 1 and vp["specular_power"] > 0
    np.testing.assert_allclose(vp["gradient"][:, 1], 1.0)  # no gradient modulation
    op, col = vp["opacity"], vp["color"]
    assert np.all(np.diff(op[:, 0]) > 0) and np.all(np.diff(col[:, 0]) > 0)
    x, s = probe_values()
    rgb = np.column_stack([np.interp(x, col[:, 0], col[:, c]) for c in (1, 2, 3)])
    check_same_tf(tf, x, s, np.interp(x, op[:, 0], op[:, 1]), rgb)


def test_slicer_opacity_is_converted_to_one_world_unit():
    tf = ct_tf()
    # Voxels of 0.5 mm: Slicer's unit is 1 mm, two voxels, so a -> 1 - (1 - a)^2.
    vp = read_vp(export_tf(tf, "slicer", unit_distance=0.5))
    x, s = probe_values()
    op, col = vp["opacity"], vp["color"]
    rgb = np.column_stack([np.interp(x, col[:, 0], col[:, c]) for c in (1, 2, 3)])
    check_same_tf(tf, x, s, np.interp(x, op[:, 0], op[:, 1]), rgb, unit_scale=2.0)


def test_vtk_snippet_runs_and_vtk_evaluates_the_same_tf(tmp_path):
    pytest.importorskip("vtk")
    tf = ct_tf()
    path = write_export(tf, "vtk", tmp_path / "tf.vtk.py", unit_distance=0.8)
    ns = runpy.run_path(str(path))
    ctf, otf, prop = ns["color_tf"], ns["opacity_tf"], ns["volume_property"]
    assert prop.GetScalarOpacityUnitDistance() == pytest.approx(0.8)
    assert prop.GetRGBTransferFunction() is ctf and prop.GetScalarOpacity() is otf
    assert otf.GetRange() == (LO, HI)
    x, s = probe_values(1500)
    opacity = np.array([otf.GetValue(v) for v in x])
    rgb = np.array([ctf.GetColor(v) for v in x])
    check_same_tf(tf, x, s, opacity, rgb)


def test_1dt_table_spans_the_range_per_voxel():
    tf = ct_tf()
    table = read_1dt(export_tf(tf, "1dt"))
    assert len(table) == 4096
    s = np.linspace(0, 1, 4096)
    np.testing.assert_allclose(table[:, 3], tf.opacity(s), atol=1e-5)
    np.testing.assert_allclose(table[:, :3], tf.color(s), atol=1e-5)


def test_explicit_value_range_overrides_and_is_needed_without_one():
    tf = ct_tf(value_range=None)
    with pytest.raises(TransferFunctionError) as info:
        export_tf(tf, "paraview")
    assert "value range" in info.value.message and info.value.hint
    _, rgbp, pts = read_paraview(export_tf(tf, "paraview", value_range=(0, 255)))
    assert pts[0, 0] == 0.0 and pts[-1, 0] == 255.0
    # The vessel Gaussian at 0.5 peaks at 127.5 in these units.
    assert np.interp(127.5, pts[:, 0], pts[:, 1]) == pytest.approx(0.9, abs=OPACITY_ATOL)
    with_range = ct_tf()
    _, _, pts2 = read_paraview(export_tf(with_range, "paraview", value_range=(0, 255)))
    assert pts2[-1, 0] == 255.0
    with pytest.raises(TransferFunctionError):
        export_tf(tf, "slicer", value_range=(5, 5))


def test_unknown_format_and_bad_unit_distance():
    with pytest.raises(TransferFunctionError, match="Unknown export format") as info:
        export_tf(ct_tf(), "blender")
    assert "paraview" in info.value.hint
    with pytest.raises(TransferFunctionError):
        export_tf(ct_tf(), "vtk", unit_distance=0)


def test_every_format_has_a_suffix_and_writes(tmp_path):
    tf = ct_tf()
    for fmt, suffix in EXPORT_FORMATS.items():
        p = write_export(tf, fmt, export_path(tmp_path / "rank01", fmt))
        assert p.name == "rank01" + suffix
        assert p.read_text() == export_tf(tf, fmt)
    assert not list(tmp_path.glob(".*.tmp"))
