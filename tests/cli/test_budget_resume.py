"""`intuitf optimize` keeps its promises under budget stops, resumes, kill -9, a hanging or moved
server, and credentials in URLs (issue 8, items 1 and 4). The fake server's own request count
is the judge of what was spent."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from intuitf.testing.fake_mllm import FakeMLLMServer
from intuitf.testing.images import red_disc

COMMON = ["--population", "16", "--generations", "4", "--size", "48", "--output-size", "48",
          "--top", "1", "--seed", "3", "--text", "red bone, faint blue skin"]  # fmt: skip
#: MLLMJudge's default concurrency: the most calls that can be in flight when a process dies.
MAX_CONCURRENCY = 32


def _intuitf(*args, check=True, timeout=300):
    proc = subprocess.run(
        [sys.executable, "-m", "intuitf", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=dict(os.environ, PYTHONUNBUFFERED="1", COLUMNS="200"),
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}")
    return proc


def _paid(out: str) -> int:
    """The paid-call count of the end summary."""
    m = re.search(r"(\d+) paid call", out)
    assert m, out
    return int(m.group(1))


@pytest.mark.slow
def test_a_resume_with_a_larger_budget_pays_exactly_the_difference(tmp_path):
    run = tmp_path / "run"
    with FakeMLLMServer(target=red_disc()) as srv:
        spec = ["--evaluator", srv.base_url]
        first = _intuitf("optimize", "phantom", *COMMON, *spec, "--budget-calls", "60",
                         "-o", str(run), check=False)  # fmt: skip
        assert first.returncode == 3, (first.stdout, first.stderr)
        assert srv.stats.requests == 60  # the run wanted more: exactly the budget was used
        assert _paid(first.stdout) == 60  # and the summary says what the server saw
        second = _intuitf("optimize", "--resume", str(run), "--budget-calls", "100", check=False)
        assert second.returncode == 3, (second.stdout, second.stderr)
        assert srv.stats.requests == 100  # 40 more, not 52: the interrupted generation's too
        assert _paid(second.stdout) == 100
        journal = [json.loads(x) for x in (run / "journal.jsonl").read_text().splitlines()]
        assert journal[-1]["type"] == "end" and journal[-1]["cost"]["calls"] == 100


@pytest.mark.slow
def test_budget_stop_resume_kill_and_resume_never_pay_beyond_the_budget(tmp_path):
    run = tmp_path / "run"
    budget = 150
    with FakeMLLMServer(target=red_disc(), latency=0.05) as srv:
        spec = ["--evaluator", srv.base_url]
        first = _intuitf("optimize", "phantom", *COMMON, *spec, "--budget-calls", "50",
                         "-o", str(run), check=False)  # fmt: skip
        assert first.returncode == 3 and srv.stats.requests <= 50
        # Resume with the full budget, and kill -9 it in the middle of a round.
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "intuitf",
                "optimize",
                "--resume",
                str(run),
                "--budget-calls",
                str(budget),
            ],  # fmt: skip
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.time() + 120
        while time.time() < deadline and srv.stats.requests < 100:
            time.sleep(0.01)
        in_flight = srv.stats.in_flight
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
        assert 100 <= srv.stats.requests < budget, "the kill did not land mid-run"
        assert in_flight > 0
        last = _intuitf("optimize", "--resume", str(run), "--budget-calls", str(budget),
                        check=False)  # fmt: skip
        assert last.returncode == 3, (last.stdout, last.stderr)
        total = srv.stats.requests
    assert total <= budget + MAX_CONCURRENCY  # the promise of the issue
    # In fact every request is recorded before it is sent, so calls a killed process had under
    # way count against the budget on resume: not even those go beyond it.
    assert total <= budget
    assert _paid(last.stdout) <= total
    # The summary also names the requests the killed process sent without seeing an answer,
    # so what it prints accounts for everything the server saw.
    lost = re.search(r"plus (\d+) request", last.stdout)
    assert lost and _paid(last.stdout) + int(lost.group(1)) >= total


def test_a_negative_budget_is_refused(tmp_path):
    for flag in ("--budget-calls", "--budget-usd"):
        proc = _intuitf("optimize", "phantom", "--evaluator", "http://127.0.0.1:9/v1", flag,
                        "-1", "-o", str(tmp_path / "r"), check=False)  # fmt: skip
        assert proc.returncode == 2, (proc.stdout, proc.stderr)
        assert "Traceback" not in proc.stderr and flag in proc.stderr
        assert not (tmp_path / "r" / "run.json").exists()


def test_a_hanging_server_fails_fast_with_short_timeouts_and_says_how_to_resume(tmp_path):
    run = tmp_path / "run"
    with FakeMLLMServer(target=red_disc(), faults={"hang": 1.0}, hang_seconds=120) as srv:
        t0 = time.perf_counter()
        proc = _intuitf("optimize", "phantom", *COMMON, "--evaluator", srv.base_url,
                        "--request-timeout", "0.5", "--answer-deadline", "1.5", "-o", str(run),
                        check=False)  # fmt: skip
        took = time.perf_counter() - t0
    assert proc.returncode == 3, (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr
    out = " ".join(proc.stdout.split())
    assert "no answer within 1.5 s" in out and "timed out" in out
    assert f"intuitf optimize --resume {run}" in out
    assert took < 60  # the command's start-up and one round's deadline, not 5 minutes


@pytest.mark.slow
def test_resume_with_a_new_base_url_moves_the_run_and_records_it(tmp_path):
    run = tmp_path / "run"
    with FakeMLLMServer(target=red_disc()) as old, FakeMLLMServer(target=red_disc()) as new:
        first = _intuitf("optimize", "phantom", *COMMON, "--evaluator", old.base_url + "#m1",
                         "--budget-calls", "60", "-o", str(run), check=False)  # fmt: skip
        assert first.returncode == 3
        asked_old = old.stats.requests
        moved = _intuitf(
            "optimize", "--resume", str(run), "--base-url", new.base_url, "--budget-calls", "1000"
        )
        assert old.stats.requests == asked_old  # the old address is not called again
        assert new.stats.requests > 0
    assert "Moving this run" in moved.stdout
    record = json.loads((run / "run.json").read_text())
    assert len(record["judges"]) == 2 and record["judges"][1]["from_generation"] >= 1
    assert f"127.0.0.1:{new.port}" in json.dumps(record)  # where it went, for the next resume
    journal = [json.loads(x) for x in (run / "journal.jsonl").read_text().splitlines()]
    assert any(e["type"] == "judge" for e in journal)


@pytest.mark.slow
def test_credentials_in_a_url_are_never_stored_or_shown(tmp_path):
    run = tmp_path / "run"
    with FakeMLLMServer(target=red_disc()) as srv:
        url = srv.base_url.replace("http://", "http://me:SECRETKEY123@")
        first = _intuitf("optimize", "phantom", *COMMON, "--evaluator", url, "--budget-calls",
                         "20", "-o", str(run), check=False)  # fmt: skip
        assert first.returncode == 3, (first.stdout, first.stderr)
        assert srv.stats.requests == 20
        # Resuming at the recorded address needs the key again: it was not stored.
        again = _intuitf("optimize", "--resume", str(run), "--budget-calls", "30", check=False)
        assert again.returncode != 0 and "--base-url" in again.stdout + again.stderr
        third = _intuitf("optimize", "--resume", str(run), "--base-url", url, "--budget-calls",
                         "30", check=False)  # fmt: skip
        assert third.returncode == 3 and srv.stats.requests == 30
    shown = "".join(p.stdout + p.stderr for p in (first, again, third))
    assert "SECRETKEY123" not in shown
    for f in run.rglob("*"):
        if f.is_file() and f.suffix in (".json", ".jsonl", ".html", ".txt", ""):
            assert "SECRETKEY123" not in f.read_text(errors="replace"), f
    assert "me:***@" in (run / "run.json").read_text()


def test_run_folder_of_a_budget_stop_is_resumable_by_path_only(tmp_path):
    """The smallest budget case: zero calls allowed is a clean stop, not an error."""
    run = tmp_path / "run"
    with FakeMLLMServer(target=red_disc()) as srv:
        proc = _intuitf("optimize", "phantom", *COMMON, "--evaluator", srv.base_url,
                        "--budget-calls", "0", "-o", str(run), check=False)  # fmt: skip
        assert proc.returncode == 3 and srv.stats.requests == 0
    assert "budget" in proc.stdout.lower() and Path(run / "run.json").exists()


@pytest.mark.slow
def test_an_overwritten_run_counts_only_its_own_spend(tmp_path):
    run = tmp_path / "run"
    with FakeMLLMServer(target=red_disc()) as srv:
        spec = ["--evaluator", srv.base_url]
        _intuitf("optimize", "phantom", *COMMON, *spec, "--budget-calls", "30", "-o", str(run),
                 check=False)  # fmt: skip
        before = srv.stats.requests
        again = _intuitf("optimize", "phantom", *COMMON, "--seed", "4", *spec, "--budget-calls",
                         "20", "--overwrite", "-o", str(run), check=False)  # fmt: skip
        assert again.returncode == 3, (again.stdout, again.stderr)
        assert srv.stats.requests - before == 20
        assert _paid(again.stdout) == 20  # not 50: the replaced run's spend is not this run's
