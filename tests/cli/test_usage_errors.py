"""Usage errors are one message and exit code 2, whichever click Typer is built on, and every
choice-valued option lists its valid values (issue 8, item 5)."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from types import SimpleNamespace

import pytest

import intuitf.cli.app as cli_app


def _intuitf(*args, timeout=240):
    """The real entry point (the console script's ``console_main``) in a fresh process."""
    code = "import sys; from intuitf.cli.app import console_main; sys.argv[0] = 'intuitf'; console_main()"
    return subprocess.run(
        [sys.executable, "-c", code, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, COLUMNS="200"),
    )


def _flat(text: str) -> str:
    return " ".join(text.split())


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["serv"], ["No such command", "serv"]),
        (["render", "phantom", "--bogus"], ["No such option", "--bogus"]),  # wording varies
        (["info"], ["Missing argument"]),
    ],
)
def test_mistyped_command_or_option_is_a_usage_error(args, says):
    proc = _intuitf(*args)
    assert proc.returncode == 2, proc.stderr
    assert all(s in proc.stderr for s in says), proc.stderr
    assert "Traceback" not in proc.stderr and "typer._click" not in proc.stderr


@pytest.mark.parametrize("module", ["typer._click.exceptions", "click.exceptions"])
def test_usage_errors_of_either_click_flavour_are_shown_not_raised(module, monkeypatch, capsys):
    try:
        exceptions = importlib.import_module(module)
    except ImportError:
        pytest.skip(f"{module} is not installed")

    def app(**_):
        raise exceptions.NoSuchOption("--bogus")

    monkeypatch.setattr(cli_app, "app", app)
    with pytest.raises(SystemExit) as ei:
        cli_app.main(["render", "--bogus"])
    assert ei.value.code == 2
    err = capsys.readouterr().err
    assert "No such option" in err and "--bogus" in err  # (wording differs between clicks)

    import typer

    # The vendored click raises typer's own Abort; stand-alone click has its own.
    abort_class = getattr(exceptions, "Abort", typer.Abort)

    def abort(**_):
        raise abort_class()

    monkeypatch.setattr(cli_app, "app", abort)
    with pytest.raises(SystemExit) as ei:
        cli_app.main([])
    assert ei.value.code == 130


@pytest.mark.parametrize(
    ("args", "values"),
    [
        (["optimize", "phantom", "--explorer", "banana"], "'ga', 'paper-ga', 'cmaes', 'random'"),
        (["optimize", "phantom", "--protocol", "swiss"], "'efficient', 'paper'"),
        (["batch", "ref.png", "phantom", "--explorer", "banana"], "'ga', 'paper-ga', 'cmaes'"),
        (["batch", "ref.png", "phantom", "--protocol", "swiss"], "'efficient', 'paper'"),
        (["export", "x.json", "--to", "blender"], "'paraview', 'slicer', 'vtk', '1dt'"),
        (["info", "phantom", "--byte-order", "middle"], "'little', 'big'"),
        (["info", "phantom", "--dtype", "uint12"], "'uint8', 'int8', 'uint16'"),
    ],
)
def test_choice_options_list_their_values(args, values, capsys):
    with pytest.raises(SystemExit) as ei:
        cli_app.main(args)
    err = _flat(capsys.readouterr().err)
    assert ei.value.code == 2
    assert "Invalid value" in err and values in err, err
    assert "Traceback" not in err


def test_choice_options_accept_any_case(tmp_path, capsys):
    import numpy as np

    p = tmp_path / "v_4x4x4.raw"
    (np.arange(64) * 300).astype(">u2").tofile(p)
    cli_app.main(["info", str(p), "--byte-order", "BIG", "--dtype", "UINT16"])
    out = _flat(capsys.readouterr().out)
    assert "uint16" in out and "0 .. 18900" in out


def test_summary_names_the_report_only_when_there_is_one(tmp_path, monkeypatch):
    """...and its paths and the command to continue stay whole, however long: Rich broke a
    path wider than the console with a newline, and a copied ``--resume PATH`` failed."""
    from intuitf.cli import optimize_cmds
    from intuitf.evaluator.types import Cost

    run_dir = tmp_path / ("a-run-folder-with-a-long-name-" * 3)
    run_dir.mkdir()
    outcome = SimpleNamespace(
        best=[],
        cost=Cost(),
        generations_done=0,
        run_dir=run_dir,
        completed=False,
        message="Stopped: the call budget is spent.",
    )
    session = SimpleNamespace(volume=SimpleNamespace(value_range=(0.0, 1.0)))
    monkeypatch.setattr(optimize_cmds, "_print_match_stats", lambda outcome: None)
    with optimize_cmds.console.capture() as cap:
        optimize_cmds._print_summary(outcome, session, 0.0)
    assert "(report:" not in cap.get()
    (run_dir / "report.html").write_text("<html></html>")
    with optimize_cmds.console.capture() as cap:
        optimize_cmds._print_summary(outcome, session, 0.0)
    out = cap.get()
    assert len(str(run_dir)) > optimize_cmds.console.width
    assert f"(report: {run_dir / 'report.html'})" in out
    assert f"intuitf optimize --resume {run_dir}\n" in out


def test_fake_server_fault_rates_above_one_are_a_usage_error():
    proc = subprocess.run(
        [sys.executable, "-m", "intuitf.testing.fake_mllm", "--port", "0",
         "--fault-rate", "malformed=0.6", "--fault-rate", "refusal=0.6"],
        capture_output=True,
        text=True,
        timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2
    assert "add up to 1.2" in proc.stderr and "Traceback" not in proc.stderr
    proc = subprocess.run(
        [sys.executable, "-m", "intuitf.testing.fake_mllm", "--fault-rate", "hang=1.5"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and "within 0..1" in proc.stderr


def test_version_prints_the_version_and_exits_0():
    from intuitf import __version__

    proc = _intuitf("--version")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"intuitf {__version__}"


def test_a_ctrl_c_after_the_command_ends_the_process_quietly():
    """After the command, SIGINT is back to the default action: a key pressed while the
    interpreter shuts down (joining worker threads) ends it without a traceback."""
    code = (
        "import signal, sys; from intuitf.cli.app import console_main\n"
        "sys.argv[:] = ['intuitf', '--version']\n"
        "try:\n    console_main()\nexcept SystemExit:\n    pass\n"
        "print(signal.getsignal(signal.SIGINT) is signal.SIG_DFL)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "True"


def test_an_error_quotes_a_long_path_whole(tmp_path, capsys):
    """The error and what to do are soft-wrapped: the terminal folds a long line, and a path
    in it copies whole (Rich broke it with a newline at 80 columns)."""
    missing = tmp_path / ("a-folder-with-a-long-name-" * 4) / "ct_8x8x8_uint8.raw"
    with pytest.raises(SystemExit) as ei:
        cli_app.main(["info", str(missing)])
    assert ei.value.code == 2
    err = capsys.readouterr().err
    assert str(missing) in err and len(str(missing)) > 80


@pytest.mark.parametrize(
    ("option", "suggested"),
    [
        ("--workrs", "--workers"),
        ("--ray-timout", "--ray-timeout"),
        ("--ray-address", "--ray [ADDRESS]"),  # the address follows --ray
    ],
)
def test_a_mistyped_batch_option_names_the_one_meant(option, suggested, capsys):
    """``batch`` lets unknown options through (for ``--ray ADDRESS``) and rejects them itself:
    with the option meant, as Click does for every other command."""
    with pytest.raises(SystemExit) as ei:
        cli_app.main(["batch", "ref.png", option, "2", "phantom"])
    assert ei.value.code == 2
    err = _flat(capsys.readouterr().err)
    assert f"No such option: {option} (Possible options: {suggested}" in err
