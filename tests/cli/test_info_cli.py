"""``intuitf info``: prints the facts and exits 0; a bad file exits 2 with a message only."""

from __future__ import annotations

import gzip
import subprocess
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from intuitf.cli.app import app, main
from intuitf.cli.options import parse_triple, volume_kwargs
from intuitf.cli.volume_cmds import sparkline
from intuitf.errors import VolumeError


def test_info_on_phantom_and_raw_file(tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["info", "phantom"])
    assert res.exit_code == 0, res.output
    assert "phantom" in res.output and "96 x 96 x 96" in res.output and "uint8" in res.output
    assert "materials" in res.output

    a = np.arange(6 * 5 * 4, dtype=np.uint16).reshape(4, 5, 6) * 7
    p = tmp_path / "v_6x5x4_uint16.raw.gz"
    p.write_bytes(gzip.compress(a.tobytes()))
    res = runner.invoke(app, ["info", str(p), "--spacing", "0.5,0.5,2"])
    assert res.exit_code == 0, res.output
    assert "6 x 5 x 4" in res.output and "uint16" in res.output
    assert "0 .. 833" in res.output
    assert "2.5 x 2 x 6" in res.output  # physical size: (n - 1) * spacing


def test_bad_file_exits_2_with_message(tmp_path, capsys):
    p = tmp_path / "v.raw"
    p.write_bytes(bytes(100))
    with pytest.raises(SystemExit) as ei:
        main(["info", str(p), "--shape", "4,4,4", "--dtype", "uint8"])
    assert ei.value.code == 2
    err = " ".join(capsys.readouterr().err.split())  # rich wraps long lines
    assert "64 bytes" in err and "100 bytes" in err and "Traceback" not in err


def test_subprocess_error_has_no_traceback(tmp_path):
    p = tmp_path / "broken_8x8x8_uint8.raw.gz"
    p.write_bytes(b"\x1f\x8b\x08\x00garbage-garbage-garbage")
    proc = subprocess.run(
        [sys.executable, "-m", "intuitf", "info", str(p)], capture_output=True, text=True
    )
    assert proc.returncode == 2
    err = "".join(proc.stderr.split())  # the console may wrap long paths
    assert "broken_8x8x8_uint8.raw.gz" in err and "corrupt" in err
    assert "Traceback" not in proc.stderr + proc.stdout


def test_option_parsing():
    assert parse_triple("256,256,128", "shape", int) == (256, 256, 128)
    assert parse_triple("256x256x128", "shape", int) == (256, 256, 128)
    assert parse_triple("1, 1, 2.5", "spacing") == (1.0, 1.0, 2.5)
    assert volume_kwargs(shape="4,5,6", dtype="uint8", byte_order="Big", max_dim=64) == {
        "shape": (4, 5, 6),
        "dtype": "uint8",
        "byte_order": "big",
        "max_dim": 64,
    }
    assert volume_kwargs() == {}
    for bad in ("1,2", "a,b,c", "1,0,3"):
        with pytest.raises(VolumeError, match="--shape"):
            parse_triple(bad, "shape", int)
    with pytest.raises(VolumeError, match="--byte-order"):
        volume_kwargs(byte_order="middle")


def test_sparkline_shape():
    s = sparkline(np.array([1000, 10, 0, 0, 10, 1000]), width=6)
    assert len(s) == 6 and s[0] == s[-1] == "█" and s[2] == " "
