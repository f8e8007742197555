"""PNG writing and picture reading."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.errors import IntuitfError
from intuitf.imageio import load_image, load_image_rgba, png_bytes, save_png


def test_png_round_trip_and_atomic_write(tmp_path):
    img = (np.arange(24 * 32 * 3) % 251).astype(np.uint8).reshape(24, 32, 3)
    p = save_png(img, tmp_path / "sub" / "a.png")
    np.testing.assert_array_equal(load_image(p), img)
    np.testing.assert_array_equal(load_image(png_bytes(img)), img)
    assert sorted(x.name for x in p.parent.iterdir()) == ["a.png"]  # no temp file left
    rgba = load_image_rgba(p)
    assert rgba.shape == (24, 32, 4) and (rgba[..., 3] == 255).all()


def test_transparent_pictures_flatten_onto_white(tmp_path):
    rgba = np.zeros((4, 4, 4), dtype=np.uint8)
    rgba[..., 0] = 255
    rgba[:2, :, 3] = 255  # top half opaque red, bottom transparent
    p = save_png(rgba, tmp_path / "t.png")
    rgb = load_image(p)
    np.testing.assert_array_equal(rgb[0, 0], [255, 0, 0])
    np.testing.assert_array_equal(rgb[3, 0], [255, 255, 255])


def test_unreadable_pictures_raise_one_clear_error(tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a picture")
    with pytest.raises(IntuitfError, match="cannot read"):
        load_image(bad)
    with pytest.raises(IntuitfError, match="no such"):
        load_image(tmp_path / "missing.png")
    with pytest.raises(IntuitfError):
        save_png(np.zeros((2, 2, 5)), tmp_path / "x.png")


# -- what a rendering records about itself, and the formats written (issue 8) ---------------
def _record():
    from intuitf.imageio import render_record
    from intuitf.render import Camera

    return render_record(Camera(azimuth=75.0, elevation=-10.0, zoom=1.5), (32, 24), "foot")


def test_png_carries_its_render_record(tmp_path):
    from intuitf.imageio import read_render_metadata

    img = np.zeros((24, 32, 3), np.uint8)
    rec = _record()
    p = save_png(img, tmp_path / "r.png", metadata=rec)
    got = read_render_metadata(p)
    assert got == rec
    assert got["camera"]["azimuth"] == 75.0 and got["size"] == [32, 24]
    assert read_render_metadata(png_bytes(img, rec)) == rec
    np.testing.assert_array_equal(load_image(p), img)  # the pixels are unchanged


def test_pictures_without_a_record_read_as_none(tmp_path):
    from PIL import Image

    from intuitf.imageio import read_render_metadata

    p = tmp_path / "plain.png"
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(p)
    assert read_render_metadata(p) is None
    assert read_render_metadata(save_png(np.zeros((4, 4, 3)), tmp_path / "n.png")) is None


def test_save_image_writes_real_jpeg_and_refuses_unknown_suffixes(tmp_path):
    from intuitf.imageio import read_render_metadata, save_image

    img = np.full((16, 16, 3), 200, np.uint8)
    p = save_image(img, tmp_path / "x.jpg", metadata=_record())
    assert p.read_bytes()[:3] == b"\xff\xd8\xff"  # JPEG, not PNG bytes under a .jpg name
    assert abs(int(load_image(p)[8, 8, 0]) - 200) <= 2
    assert read_render_metadata(p)["camera"]["azimuth"] == 75.0
    assert save_image(img, tmp_path / "y.JPEG").read_bytes()[:3] == b"\xff\xd8\xff"
    assert save_image(img, tmp_path / "z.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(IntuitfError, match=r"\.png, \.jpg, \.jpeg") as ei:
        save_image(img, tmp_path / "x.bmp")
    assert "'.bmp'" in str(ei.value)
    assert not (tmp_path / "x.bmp").exists()


def test_render_command_writes_jpeg_and_records_its_camera(tmp_path):
    import subprocess
    import sys

    from intuitf.imageio import read_render_metadata

    jpg = tmp_path / "p.jpg"
    run = [sys.executable, "-m", "intuitf", "render", "phantom", "--size", "40"]
    proc = subprocess.run([*run, "-o", str(jpg)], capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr
    assert jpg.read_bytes()[:3] == b"\xff\xd8\xff"
    png = tmp_path / "p.png"
    proc = subprocess.run(
        [*run, "-o", str(png), "--azimuth", "60", "--elevation", "5", "--orthographic"],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert proc.returncode == 0, proc.stderr
    rec = read_render_metadata(png)
    assert rec["camera"]["azimuth"] == 60.0 and rec["camera"]["elevation"] == 5.0
    assert rec["camera"]["projection"] == "orthographic"
    assert rec["size"] == [40, 40] and rec["volume"] == "phantom"
    bad = subprocess.run([*run, "-o", str(tmp_path / "p.tif")], capture_output=True, text=True)
    assert bad.returncode == 2 and ".png, .jpg, .jpeg" in " ".join(bad.stderr.split())
    assert "Traceback" not in bad.stderr and not (tmp_path / "p.tif").exists()
