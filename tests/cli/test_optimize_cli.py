"""`intuitf optimize` end to end: offline judge, a model server over HTTP, kill and resume."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from helpers.waiting import wait_for
from intuitf.testing.fake_mllm import FakeMLLMServer
from intuitf.testing.images import red_disc

COMMON = [
    "--population",
    "8",
    "--generations",
    "4",
    "--size",
    "64",
    "--output-size",
    "64",
    "--top",
    "1",
    "--seed",
    "1",
    "--text",
    "red bone, faint blue skin",
]


def _intuitf(*args, check=True, timeout=240):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.run(
        [sys.executable, "-m", "intuitf", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}")
    return proc


def _best(run: Path) -> dict:
    return json.loads((run / "best" / "rank01.tf.json").read_text())


def _generations(run: Path) -> list[int]:
    out = []
    if (run / "journal.jsonl").exists():
        for line in (run / "journal.jsonl").read_text().splitlines():
            try:
                e = json.loads(line)
            except json.JSONDecodeError:
                continue
            if e.get("type") == "generation":
                out.append(e["generation"])
    return out


def test_optimize_with_metric_judge_writes_a_run(tmp_path):
    run = tmp_path / "run"
    proc = _intuitf("optimize", "phantom", *COMMON, "-o", str(run))
    assert "Best transfer functions" in proc.stdout
    assert (run / "report.html").exists() and (run / "best" / "rank01.vp").exists()
    assert _generations(run) == [0, 1, 2, 3]
    # How the words were read is said before the run, and kept with it.
    assert "Understood:" in proc.stdout and '"bone": red' in proc.stdout
    assert json.loads((run / "run.json").read_text())["understood"][0].startswith('"bone": red')
    # The colours named in --text ("red bone, faint blue skin") are the explorer's palette.
    palette = json.loads((run / "checkpoint.json").read_text())["explorer"]["palette"]
    assert len(palette) == 2 and palette[0][0] > 0.8 and palette[1][2] > 0.8
    plain = tmp_path / "plain"
    _intuitf("optimize", "phantom", *COMMON, "--generations", "1", "--no-palette", "-o", str(plain))
    assert json.loads((plain / "run.json").read_text())["settings"]["palette_hint"] is False
    assert json.loads((plain / "checkpoint.json").read_text())["explorer"]["palette"] == []
    # A second optimize into the same folder is refused with advice, not a traceback.
    again = _intuitf("optimize", "phantom", *COMMON, "-o", str(run), check=False)
    assert again.returncode == 2 and "--resume" in again.stderr and "Traceback" not in again.stderr


def test_bad_volume_is_one_clear_message(tmp_path):
    bad = tmp_path / "scan_10x10x10_uint8.raw"
    bad.write_bytes(b"\0" * 999)
    proc = _intuitf("optimize", str(bad), "-o", str(tmp_path / "r"), check=False)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "1000" in proc.stderr


@pytest.mark.slow
def test_killed_run_resumes_with_nothing_repeated(tmp_path):
    with FakeMLLMServer(target=red_disc(), latency=0.01) as srv:
        spec = ["--evaluator", srv.base_url]
        ref = tmp_path / "ref"
        _intuitf("optimize", "phantom", *COMMON, *spec, "-o", str(ref))
        # Comparisons only: the run also names the volume's structures (one atlas request).
        uninterrupted_requests = srv.stats.requests - srv.stats.atlas_requests
        assert uninterrupted_requests > 0

        run = tmp_path / "killed"
        env = dict(os.environ, PYTHONUNBUFFERED="1")
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "intuitf",
                "optimize",
                "phantom",
                *COMMON,
                *spec,
                "-o",
                str(run),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
        )
        wait_for(lambda: _generations(run), timeout=180, what="a finished generation")
        # Into the middle of the next generation: some of its questions asked (not all, as the
        # kill lands on the first one the server sees).
        asked = srv.stats.requests
        wait_for(lambda: srv.stats.requests > asked, timeout=60, what="the next question")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        assert _generations(run), "the run never finished a generation"
        before = srv.stats.requests - srv.stats.atlas_requests
        with sqlite3.connect(run / "verdicts.sqlite") as db:
            paid = db.execute("SELECT COUNT(*) FROM answers").fetchone()[0]

        _intuitf("optimize", "--resume", str(run))
        asked_after_resume = srv.stats.requests - srv.stats.atlas_requests - before
        # Every question answered before the kill came from the cache; only the rest was asked.
        assert asked_after_resume == uninterrupted_requests - paid
        assert _best(run) == _best(ref)


def test_ctrl_c_saves_and_says_how_to_resume(tmp_path):
    # Far more generations than the test waits for, so the run is surely still going when
    # Ctrl-C arrives (with COMMON's four it sometimes finished first on a busy machine).
    long_run = [*COMMON]
    long_run[long_run.index("--generations") + 1] = "60"
    with FakeMLLMServer(target=red_disc(), latency=0.05) as srv:
        run = tmp_path / "run"
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "intuitf",
                "optimize",
                "phantom",
                *long_run,
                "--evaluator",
                srv.base_url,
                "-o",
                str(run),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=dict(os.environ, PYTHONUNBUFFERED="1"),
        )
        wait_for((run / "checkpoint.json").exists, timeout=180, what="the first checkpoint")
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, (out, err)
        assert "Traceback" not in err
        assert "--resume" in out
        journal = [json.loads(x) for x in (run / "journal.jsonl").read_text().splitlines()]
        assert journal[-1]["type"] == "end" and journal[-1]["reason"] == "interrupted"
        assert json.loads((run / "checkpoint.json").read_text())["generation"] >= 1


def test_lost_model_server_ends_cleanly(tmp_path):
    with FakeMLLMServer(target=red_disc()) as srv:
        url = srv.base_url
    # The server is gone now: nothing listens on that port any more.
    run = tmp_path / "run"
    proc = _intuitf("optimize", "phantom", *COMMON, "--evaluator", url, "-o", str(run), check=False)
    assert proc.returncode == 3, (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    assert "--resume" in proc.stdout
    assert (run / "run.json").exists()


def test_spent_budget_stops_cleanly_and_a_larger_one_resumes(tmp_path):
    with FakeMLLMServer(target=red_disc()) as srv:
        run = tmp_path / "run"
        spec = ["--evaluator", srv.base_url]
        first = _intuitf("optimize", "phantom", *COMMON, *spec, "--budget-calls", "30",
                         "-o", str(run), check=False)  # fmt: skip
        assert first.returncode == 3, (first.stdout, first.stderr)
        assert "budget" in first.stdout.lower() and "--resume" in first.stdout
        assert "Traceback" not in first.stderr
        paid_before = srv.stats.requests
        assert paid_before <= 30
        _intuitf("optimize", "--resume", str(run), "--budget-calls", "1000")
        assert _generations(run)[-1] == 3
        assert (run / "best" / "rank01.tf.json").exists()
