"""``intuitf render`` end to end on the built-in phantom."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.cli.app import main
from intuitf.cli.render_cmds import parse_color, parse_size
from intuitf.errors import RenderError
from intuitf.imageio import load_image


def test_render_writes_a_png_of_the_volume(tmp_path):
    out = tmp_path / "p.png"
    main(["render", "phantom", "--size", "64x48", "--background", "white", "-o", str(out)])
    img = load_image(out)
    assert img.shape == (48, 64, 3)
    np.testing.assert_array_equal(img[0, 0], [255, 255, 255])  # background corner
    assert (img.sum(axis=2) < 600).mean() > 0.05  # the head covers part of the picture


def test_render_reports_bad_options_without_traceback(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["render", "phantom", "--background", "pink", "-o", str(tmp_path / "x.png")])
    assert exc.value.code == 2
    assert "not a colour" in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()


def test_option_parsers():
    assert parse_color("#ff8000") == (1.0, 128 / 255, 0.0)
    assert parse_color("255,0,0") == (1.0, 0.0, 0.0)
    assert parse_color("0.5,0.5,0.5") == (0.5, 0.5, 0.5)
    assert parse_size("512") == 512 and parse_size("640x480") == (640, 480)
    with pytest.raises(RenderError):
        parse_size("big")
