"""Cameras in the VTK/ParaView form give the same view as intuitf's orbit form, and pictures
for agents stay under their byte budget whatever the content."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from intuitf.errors import RenderError
from intuitf.mcp.camera import from_vtk, parse_camera, to_vtk
from intuitf.mcp.pictures import encode, image_tokens
from intuitf.render import Camera

EXTENT = (120.0, 90.0, 60.0)


@pytest.mark.parametrize(
    "cam",
    [
        Camera(),
        Camera(azimuth=30, elevation=20),
        Camera(azimuth=210, elevation=-35, roll=25, zoom=1.7, pan=(0.1, -0.05)),
        Camera(azimuth=80, elevation=90),
        Camera(azimuth=-120, elevation=-90, zoom=0.6),
        Camera(azimuth=15, elevation=10, zoom=2.5, projection="orthographic"),
    ],
)
def test_vtk_form_round_trips_to_the_same_view(cam):
    back = from_vtk(to_vtk(cam, EXTENT), EXTENT)
    f1, f2 = cam.frame(EXTENT, 64, 64), back.frame(EXTENT, 64, 64)
    for a, b in ((f1.forward, f2.forward), (f1.up, f2.up), (f1.right, f2.right)):
        assert np.allclose(a, b, atol=1e-6)
    assert f1.half_height == pytest.approx(f2.half_height, rel=1e-5)
    assert back.pan == pytest.approx(cam.pan, abs=1e-6)
    assert back.projection == cam.projection


def test_vtk_cameras_mean_what_paraview_means():
    cx, cy, cz = (e / 2 for e in EXTENT)
    # In front (-y), +z up: intuitf's azimuth 0, elevation 0.
    front = parse_camera({"position": [cx, cy - 500, cz], "focal_point": [cx, cy, cz],
                          "view_up": [0, 0, 1]}, EXTENT)  # fmt: skip
    assert (front.azimuth, front.elevation, front.roll) == pytest.approx((0, 0, 0), abs=1e-9)
    # From +x: azimuth 90. From above with +y up: elevation 90.
    side = parse_camera({"position": [cx + 500, cy, cz], "focal_point": [cx, cy, cz]}, EXTENT)
    assert side.azimuth == pytest.approx(90) and side.elevation == pytest.approx(0, abs=1e-9)
    top = parse_camera({"position": [cx, cy, cz + 500], "focal_point": [cx, cy, cz],
                        "view_up": [0, 1, 0]}, EXTENT)  # fmt: skip
    assert top.elevation == pytest.approx(90) and top.azimuth == pytest.approx(0, abs=1e-9)
    # A view-up tilted to the right turns the picture: roll.
    tilted = parse_camera({"position": [cx, cy - 500, cz], "focal_point": [cx, cy, cz],
                           "view_up": [np.sin(0.3), 0, np.cos(0.3)]}, EXTENT)  # fmt: skip
    assert abs(tilted.roll) == pytest.approx(np.degrees(0.3))
    # Twice as far with the same view angle: half the size.
    near = parse_camera({"position": [cx, cy - 300, cz], "focal_point": [cx, cy, cz]}, EXTENT)
    far = parse_camera({"position": [cx, cy - 600, cz], "focal_point": [cx, cy, cz]}, EXTENT)
    assert near.zoom == pytest.approx(2 * far.zoom)
    # A focal point right of the centre moves the volume left in the picture.
    right = parse_camera({"position": [cx + 20, cy - 500, cz], "focal_point": [cx + 20, cy, cz]},
                         EXTENT)  # fmt: skip
    assert right.pan[0] < 0 and right.pan[1] == pytest.approx(0, abs=1e-9)


@pytest.mark.parametrize(
    "bad, words",
    [
        ("front", "JSON object"),
        ({"position": [0, 0, 0], "focal_point": [0, 0, 0]}, "same point"),
        ({"position": [0, -9, 0], "focal_point": [0, 0, 0], "view_up": [0, 1, 0]}, "parallel"),
        ({"position": [0, -9, 0], "view_angle": 0}, "view_angle"),
        ({"position": [0, -9, 0], "parallel_scale": -1}, "parallel_scale"),
        ({"position": [0, -9, float("nan")]}, "finite"),
        ({"position": [0, -9, 0], "zoom": 2}, "cannot also have"),
        ({"azimuth": 0, "yaw": 3}, "Unknown camera field"),
        ({"zoom": 0}, "zoom must be positive"),
    ],
)
def test_bad_cameras_say_what_is_wrong(bad, words):
    with pytest.raises(RenderError, match=words):
        parse_camera(bad, EXTENT)


def test_pictures_fit_the_budget_png_when_small_jpeg_when_not():
    rng = np.random.default_rng(0)
    smooth = np.zeros((512, 512, 3), np.uint8)
    smooth[100:400, 150:350] = (200, 180, 150)
    small = encode(smooth, max_side=768)
    assert small.mime_type == "image/png" and (small.width, small.height) == (512, 512)
    noise = rng.integers(0, 256, (1024, 1024, 3), dtype=np.uint8)
    budget = 200_000
    big = encode(noise, max_side=1024, max_bytes=budget)
    assert big.wire_bytes <= budget and big.mime_type == "image/jpeg"
    decoded = Image.open(io.BytesIO(big.data))
    assert decoded.size == (big.width, big.height)
    capped = encode(noise, max_side=300)
    assert max(capped.width, capped.height) <= 300


def test_image_tokens_follow_the_published_rule():
    assert image_tokens(750, 1) == 1
    assert image_tokens(768, 768) == 787
    # Larger pictures are scaled down by the model first: cost stops growing.
    assert image_tokens(4000, 4000) == image_tokens(2000, 2000) < 1600


def test_pictures_sent_are_scaled_to_the_servers_side_files_keep_full_size(folders):
    import asyncio

    from mcp_util import call, make_config

    from intuitf.mcp import build_server
    from mcp import Client

    server, _ = build_server(make_config(folders, picture_side=128))

    async def main():
        async with Client(server) as client:
            vid = (await call(client, "open_volume", path="phantom", max_dim=32))["id"]
            return await call(client, "render", volume=vid, size=300)

    got = asyncio.run(main())
    assert (got["image"]["width"], got["image"]["height"]) == (128, 128)
    assert got["image"]["full_size"] == [300, 300]
    assert Image.open(got["path"]).size == (300, 300)
