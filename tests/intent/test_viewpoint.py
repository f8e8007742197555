"""A view that shows the object: upright along its axis, chosen by viewpoint entropy."""

from __future__ import annotations

import numpy as np

from helpers.shapes import potted_tree
from intuitf.intent.structures import build_structure_map
from intuitf.intent.viewpoint import choose_view, viewpoint_entropy
from intuitf.render import Camera
from intuitf.volume import Volume


def test_a_tree_lying_along_y_is_shown_upright():
    z_up = potted_tree()
    y_up = np.ascontiguousarray(np.transpose(z_up, (1, 0, 2)))  # data[z, y, x]: tree along +y
    smap = build_structure_map(y_up)
    assert (smap.up_axis, smap.up_sign) == (1, 1)
    choice = choose_view(smap)
    fwd, right, up = choice.camera.basis()
    assert up[1] > 0.9  # the picture's up is +y: pot below, leaves above
    assert abs(right[1]) < 1e-6 and abs(fwd[1]) < 0.5  # upright, seen from the side


def test_an_object_standing_along_z_keeps_the_classic_view():
    smap = build_structure_map(potted_tree())
    choice = choose_view(smap)
    assert (choice.camera.azimuth, choice.camera.elevation, choice.camera.roll) == (30, 20, 0)


def test_end_on_views_score_lower_than_side_views():
    # Three bars side by side along x, each of its own material: from the side all show,
    # end-on (looking along x) the first hides the others.
    d = np.full((40, 40, 40), 0.02, np.float32)
    for k, v in enumerate((0.3, 0.6, 0.9)):
        d[16:24, 16:24, 4 + 12 * k : 12 + 12 * k] = v
    smap = build_structure_map(Volume.from_array(d, value_range=(0, 1)).data)
    side = viewpoint_entropy(smap, Camera(azimuth=0.0, elevation=0.0))
    end_on = viewpoint_entropy(smap, Camera(azimuth=90.0, elevation=0.0))
    assert side > 2.0 * end_on
