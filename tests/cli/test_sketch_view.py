"""A sketch lands where it was drawn: ``optimize --sketch S --on BASE`` judges from the camera
BASE was rendered with, and the commands' default cameras agree (issue 8, item 6)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from intuitf.imageio import read_render_metadata

SMALL = ["--population", "4", "--generations", "1", "--output-size", "32", "--top", "1"]


def _intuitf(*args, timeout=300):
    return subprocess.run(
        [sys.executable, "-m", "intuitf", *args], capture_output=True, text=True, timeout=timeout
    )


def _settings(run) -> dict:
    record = json.loads((run / "run.json").read_text())
    return record.get("spec", record)["settings"]


def _strokes(path, size=(48, 48)):
    w, h = size
    layer = np.zeros((h, w, 4), np.uint8)
    layer[h // 3 : h // 2, w // 3 : w // 2] = (230, 40, 30, 255)
    Image.fromarray(layer).save(path)
    return path


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A picture made the way the README says: with `intuitf render`, not from the front."""
    d = tmp_path_factory.mktemp("base")
    p = d / "base.png"
    proc = _intuitf("render", "phantom", "-o", str(p), "--size", "48",
                    "--azimuth", "75", "--elevation", "-15", "--zoom", "1.3")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return p


def test_sketch_is_judged_from_its_base_pictures_camera(tmp_path, base):
    run = tmp_path / "run"
    sketch = _strokes(tmp_path / "strokes.png")
    proc = _intuitf("optimize", "phantom", "--sketch", str(sketch), "--on", str(base),
                    *SMALL, "-o", str(run))  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    picture = read_render_metadata(base)
    settings = _settings(run)
    assert settings["camera"] == picture["camera"]
    assert settings["camera"]["azimuth"] == 75.0 and settings["camera"]["zoom"] == 1.3
    assert settings["image_size"] == 48  # the base picture's size, as --size was not given
    # The run's own pictures carry their camera too, so they can be sketched on in turn.
    best = read_render_metadata(run / "best" / "rank01.png")
    assert best["camera"] == picture["camera"] and best["volume"] == "phantom"
    gen_best = read_render_metadata(run / "generations" / "gen000-best.png")
    assert gen_best["camera"] == picture["camera"] and gen_best["size"] == [48, 48]


def test_default_cameras_of_render_and_optimize_agree(tmp_path):
    pic = tmp_path / "r.png"
    assert _intuitf("render", "phantom", "-o", str(pic), "--size", "32").returncode == 0
    run = tmp_path / "run"
    proc = _intuitf("optimize", "phantom", "--text", "red bone", *SMALL, "--size", "32",
                    "-o", str(run))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert _settings(run)["camera"] == read_render_metadata(pic)["camera"]


def test_sketch_of_another_size_is_refused_before_the_run(tmp_path, base):
    run = tmp_path / "run"
    sketch = _strokes(tmp_path / "strokes.png", size=(50, 40))
    proc = _intuitf("optimize", "phantom", "--sketch", str(sketch), "--on", str(base),
                    *SMALL, "-o", str(run))  # fmt: skip
    assert proc.returncode == 2
    err = " ".join(proc.stderr.split())
    assert "50x40" in err and "48x48" in err, err
    assert "Traceback" not in err and not run.exists()


def test_sketch_without_strokes_is_refused(tmp_path, base):
    empty = tmp_path / "empty.png"
    Image.fromarray(np.zeros((48, 48, 4), np.uint8)).save(empty)
    proc = _intuitf("optimize", "phantom", "--sketch", str(empty), "--on", str(base),
                    *SMALL, "-o", str(tmp_path / "run"))  # fmt: skip
    assert proc.returncode == 2 and "no strokes" in proc.stderr


def test_base_without_a_camera_record_needs_the_camera(tmp_path):
    plain = tmp_path / "plain.png"
    Image.fromarray(np.full((48, 48, 3), 90, np.uint8)).save(plain)
    sketch = _strokes(tmp_path / "strokes.png")
    run = tmp_path / "run"
    args = ["optimize", "phantom", "--sketch", str(sketch), "--on", str(plain), *SMALL]
    proc = _intuitf(*args, "-o", str(run))
    assert proc.returncode == 2
    err = " ".join(proc.stderr.split())
    assert "does not record the camera" in err and "--azimuth" in err, err
    assert not run.exists()
    proc = _intuitf(*args, "--azimuth", "10", "--elevation", "5", "-o", str(run))
    assert proc.returncode == 0, proc.stderr
    cam = _settings(run)["camera"]
    assert (cam["azimuth"], cam["elevation"]) == (10.0, 5.0)


def test_camera_options_that_contradict_the_base_picture_are_refused(tmp_path, base):
    sketch = _strokes(tmp_path / "strokes.png")
    proc = _intuitf("optimize", "phantom", "--sketch", str(sketch), "--on", str(base),
                    "--azimuth", "0", *SMALL, "-o", str(tmp_path / "run"))  # fmt: skip
    assert proc.returncode == 2
    assert "rendered from azimuth 75" in " ".join(proc.stderr.split())


def test_judging_view_unit_rules(tmp_path, base):
    from intuitf.cli.views import judging_view
    from intuitf.errors import IntuitfError
    from intuitf.imageio import render_record, save_png

    sketch = tmp_path / "s.png"
    v = judging_view(None, None, None, None, None)
    assert (v.camera["azimuth"], v.camera["elevation"], v.size) == (30.0, 20.0, 256)
    v = judging_view(sketch, base, 75.0 + 360.0, None, 96, "phantom")  # same angle: fine
    assert v.camera["azimuth"] == 75.0 and v.size == 96
    v = judging_view(sketch, base, None, None, None, "foot")
    assert any("not 'foot'" in n for n in v.notes)
    wide = save_png(np.zeros((20, 40, 3)), tmp_path / "wide.png",
                    metadata=render_record({"azimuth": 5.0}, (40, 20), "phantom"))  # fmt: skip
    with pytest.raises(IntuitfError, match="square"):
        judging_view(sketch, wide, None, None, None)
    cropped = save_png(np.zeros((20, 20, 3)), tmp_path / "crop.png",
                       metadata=render_record({"azimuth": 5.0}, (40, 20), "phantom"))  # fmt: skip
    with pytest.raises(IntuitfError, match="cropped or stretched"):
        judging_view(sketch, cropped, None, None, None)
