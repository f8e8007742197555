"""``intuitf export`` and ``intuitf report`` from the command line."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from intuitf.cli.app import main
from intuitf.tf import Gaussian, GaussianTF, save_tf


def write_tf(path, value_range=(0.0, 255.0)):
    tf = GaussianTF(
        (Gaussian(0.5, 0.05, 0.4, (1.0, 0.0, 0.0)),), value_range=value_range, name="one"
    )
    return save_tf(tf, path), tf


def run_main(argv, capsys):
    """Run the CLI in-process; return (exit code, stdout, stderr with its lines joined)."""
    try:
        main(argv)
        code = 0
    except SystemExit as exc:
        code = exc.code or 0
    out = capsys.readouterr()
    return code, out.out, " ".join(out.err.split())  # rich wraps long lines


def test_export_through_python_dash_m(tmp_path):
    tf_path, tf = write_tf(tmp_path / "best.tf.json")
    out = tmp_path / "out" / "best.paraview.json"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "intuitf",
            "export",
            str(tf_path),
            "--to",
            "paraview",
            "-o",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    preset = json.loads(out.read_text())[0]
    pts = np.array(preset["Points"]).reshape(-1, 4)
    assert pts[0, 0] == 0.0 and pts[-1, 0] == 255.0
    assert np.interp(127.5, pts[:, 0], pts[:, 1]) == pytest.approx(0.4, abs=0.005)


def test_export_default_name_and_value_range_option(tmp_path, capsys):
    tf_path, _ = write_tf(tmp_path / "rank01.tf.json", value_range=None)
    code, _, err = run_main(["export", str(tf_path), "--to", "slicer"], capsys)
    assert code == 2
    assert "value range" in err and "--value-range" in err
    assert "Traceback" not in err
    code, out, _ = run_main(
        ["export", str(tf_path), "--to", "slicer", "--value-range", "-1000,3000"], capsys
    )
    assert code == 0
    vp = tmp_path / "rank01.vp"
    assert str(vp) in out.replace("\n", "")
    color_line = vp.read_text().splitlines()[8].split()
    assert float(color_line[1]) == -1000.0 and float(color_line[-4]) == 3000.0


@pytest.mark.parametrize(
    "args, message",
    [
        (["export", "{missing}", "--to", "vtk"], "no such"),
        (["export", "{bad}", "--to", "vtk"], "not valid JSON"),
        (["export", "{good}", "--to", "blender"], "'blender' is not one of 'paraview', 'slicer'"),
        (["export", "{good}", "--to", "vtk", "--value-range", "5"], "two numbers"),
        (["export", "{good}", "--to", "vtk", "--value-range", "9,1"], "LO < HI"),
        (["report", "{missing}"], "not a run folder"),
    ],
)
def test_user_errors_exit_2_with_a_message(tmp_path, capsys, args, message):
    good, _ = write_tf(tmp_path / "good.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{nope")
    paths = {"missing": tmp_path / "missing.json", "bad": bad, "good": good}
    argv = [a.format(**paths) for a in args]
    code, _, err = run_main(argv, capsys)
    assert code == 2
    assert message in " ".join(err.split())  # rich wraps long lines
    assert "Traceback" not in err


def test_report_command_builds_the_page(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({"intent": {"kind": "text", "text": "bones"}}))
    code, out, _ = run_main(["report", str(run)], capsys)
    assert code == 0
    page = (run / "report.html").read_text()
    assert "bones" in page and "report.html" in out
