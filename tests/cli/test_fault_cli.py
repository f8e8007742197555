"""Bad command lines end with one clear message and exit code 2, never a traceback, and write
nothing: bad options named by their flags, an output folder that cannot be made, empty text,
a report asked of a folder that is not a run."""

from __future__ import annotations

import pytest

from intuitf.cli.app import main


def _fails(argv, capsys) -> str:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    out = capsys.readouterr()
    assert "Traceback" not in out.err + out.out
    return " ".join((out.err + out.out).split())


def test_bad_options_are_named_by_their_flags_and_nothing_is_written(tmp_path, capsys):
    run = tmp_path / "run"
    msg = _fails(["optimize", "phantom", "--population", "2", "--seed", "-1", "--size", "10",
                  "-o", str(run)], capsys)  # fmt: skip
    assert "--population" in msg and "--seed" in msg and "--size" in msg
    assert "settings." not in msg  # the flags, not the API's field names
    assert not run.exists()


def test_an_output_folder_that_cannot_be_made(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    msg = _fails(["optimize", "phantom", "-o", str(blocker / "run")], capsys)
    assert "Cannot make the run folder" in msg and "is a file" in msg


def test_empty_text_is_refused(tmp_path, capsys):
    msg = _fails(["optimize", "phantom", "--text", "  ", "-o", str(tmp_path / "run")], capsys)
    assert "--text is empty" in msg
    assert not (tmp_path / "run").exists()


def test_report_of_a_folder_that_is_not_a_run(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("not a run")
    msg = _fails(["report", str(tmp_path)], capsys)
    assert "holds no run" in msg
    assert not (tmp_path / "report.html").exists()
    assert "does not exist" in _fails(["report", str(tmp_path / "nothing")], capsys)


def test_batch_names_bad_options_by_their_flags(tmp_path, capsys):
    msg = _fails(["batch", "ref.png", "vols", "--population", "2", "-o", str(tmp_path / "b")],
                 capsys)  # fmt: skip
    assert "--population" in msg
    assert not (tmp_path / "b").exists()


def test_batch_help_shows_the_ray_and_failure_options(capsys):
    try:
        main(["batch", "--help"])
    except SystemExit as exc:
        assert exc.code in (0, None)
    text = " ".join(capsys.readouterr().out.split())
    for flag in ("--ray", "[ADDRESS]", "--ray-timeout", "--max-failures"):
        assert flag in text


def test_serve_refuses_a_port_out_of_range_and_a_runs_file(tmp_path, capsys):
    msg = _fails(["serve", "--port", "99999", "--no-browser"], capsys)
    assert "--port" in msg and "65535" in msg
    a_file = tmp_path / "runs"
    a_file.write_text("x")
    msg = _fails(["serve", "--runs", str(a_file), "--no-browser"], capsys)
    assert "is a file, not a folder" in msg
