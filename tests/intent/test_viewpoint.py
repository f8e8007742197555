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


def head_from_the_top(n: int = 48) -> np.ndarray:
    """A synthetic head stored top first, as CT slices often are: a skull dome closing at
    z = 0, the neck cut by the scan's end at the high z end."""
    z, y, x = np.mgrid[0:n, 0:n, 0:n].astype(np.float32)
    c = (n - 1) / 2.0
    d = np.full((n, n, n), 0.02, np.float32)
    skull = (x - c) ** 2 + (y - c) ** 2 + (z - 20) ** 2 <= 18**2
    neck = ((x - c) ** 2 + (y - c) ** 2 <= 12**2) & (z >= 20)
    d[skull | neck] = 0.4
    d[skull & ((x - c) ** 2 + (y - c) ** 2 + (z - 20) ** 2 >= 15**2)] = 0.9  # the bone
    return d


def test_a_head_stored_from_the_top_is_shown_upright():
    smap = build_structure_map(head_from_the_top())
    assert (smap.up_axis, smap.up_sign) == (2, -1)
    _, _, up = choose_view(smap).camera.basis()
    assert up[2] < -0.9  # the picture's up is -z: the skull's top above, the neck below


def test_objects_closed_at_both_ends_or_cut_below_keep_z_up():
    head = head_from_the_top()
    assert build_structure_map(np.ascontiguousarray(head[::-1])).up_sign == 1  # neck first
    assert build_structure_map(potted_tree()).up_sign == 1  # closed at both ends


def test_the_stanford_head_is_upright_and_the_other_volumes_keep_their_views(data_dir):
    from helpers.data import data_file
    from intuitf.intent.hints import structure_map_of
    from intuitf.volume import load_volume

    head = structure_map_of(load_volume(data_file("ctheadstanford_256x256x113_uint16.raw.gz"),
                                        max_dim=96))  # fmt: skip
    assert (head.up_axis, head.up_sign) == (2, -1)  # slice 1 is the top of the head
    for name in ("tooth_103x94x161_uint8.raw.gz", "foot_zfp8lossy_256x256x256_uint8.raw.gz",
                 "engine_256x256x128_uint8.raw.gz", "chestlidc2_256x256x133_uint8.raw.gz",
                 "headsq_64x64x93_int16.raw.gz"):  # fmt: skip
        smap = structure_map_of(load_volume(data_file(name), max_dim=96))
        assert (smap.up_axis, smap.up_sign) == (2, 1), name
