"""``intuitf batch`` end to end: the metric judge and the fake model server, on the process
pool and on a local Ray instance; killed and resumed, stopped by its budget and resumed; the
shared budget holds, and every volume's result is the same whichever way it was reached."""

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
from intuitf.batch import BatchRequest, run_batch
from intuitf.imageio import load_image
from intuitf.session.lock import in_use
from intuitf.testing.fake_mllm import FakeMLLMServer, Latency

TINY = dict(population=6, generations=2, image_size=32, output_size=48, top_k=1, seed=1,
            stages=[["customize", 2]])  # fmt: skip


def _request(inputs: dict, root: Path, **kw) -> BatchRequest:
    args = dict(
        root=str(root),
        reference=str(inputs["tf"]),
        reference_volume=str(inputs["ref_volume"]),
        volumes=[str(inputs["vols"])],
        settings=dict(TINY),
        reader={"max_dim": 32},
        workers=2,
        per_worker=2,
    )
    args.update(kw)
    return BatchRequest(**args)


def _bests(root: Path) -> dict[str, dict]:
    out = {}
    for run in sorted((root / "runs").iterdir()):
        p = run / "best" / "rank01.tf.json"
        if p.exists():
            out[run.name] = json.loads(p.read_text())
    return out


def _answers(root: Path) -> int:
    """Answers already paid for and kept in the runs' verdict stores."""
    n = 0
    for db in (root / "runs").glob("*/verdicts.sqlite"):
        with sqlite3.connect(db) as con:
            n += con.execute("SELECT COUNT(*) FROM answers").fetchone()[0]
    return n


def _statuses(summary: dict) -> dict[str, str]:
    return {v["key"]: v["status"] for v in summary["volumes"]}


# -- the offline judge -------------------------------------------------------------------------
@pytest.mark.slow
def test_metric_batch_on_the_pool_summarises_and_a_rerun_skips_finished_volumes(
    batch_inputs, tmp_path
):
    root = tmp_path / "out"
    req = _request(
        batch_inputs, root, volumes=[str(batch_inputs["vols"]), str(tmp_path / "gone.npy")]
    )
    summary = run_batch(req)
    st = _statuses(summary)
    assert st.pop("gone") == "failed"  # reported and skipped; the batch went on
    assert set(st.values()) == {"completed"} and len(st) >= 3
    gone = next(v for v in summary["volumes"] if v["key"] == "gone")
    assert "no such file" in gone["message"] and gone["flagged"]
    for v in summary["volumes"]:
        if v["status"] == "completed":
            assert 0.0 < v["similarity"] <= 1.0 and v["start_similarity"] is not None
            assert (root / v["best_png"]).exists() and v["render_s"] > 0
    on_disk = json.loads((root / "summary.json").read_text())
    assert on_disk["totals"]["completed"] == len(st)
    sheet = load_image(root / "contact_sheet.png")
    assert sheet.shape[0] > 100 and sheet.shape[1] > 300
    html = (root / "report.html").read_text()
    assert "gone" in html and 'class="flag"' in html
    before = _bests(root)

    again = run_batch(req)  # the same command again: finished volumes are not run again
    skipped = [v for v in again["volumes"] if v.get("skipped")]
    assert len(skipped) == len(st)
    assert _bests(root) == before


def test_a_tf_is_carried_and_a_changed_batch_is_refused(batch_inputs, tmp_path):
    root = tmp_path / "out"
    req = _request(batch_inputs, root, volumes=[str(next(batch_inputs["vols"].glob("*32*.npy")))],
                   settings={**TINY, "generations": 1, "stages": [["customize", 1]]})  # fmt: skip
    run_batch(req)
    spec = json.loads(next((root / "runs").glob("*/run.json")).read_text())["spec"]
    assert len(spec["initial"]) == 1 and spec["initial"][0]["name"] == "carried"
    assert spec["intent"]["kind"] == "image"
    changed = _request(batch_inputs, root, settings={**TINY, "population": 8})
    from intuitf.errors import IntuitfError

    with pytest.raises(IntuitfError, match="other choices .*settings.population"):
        run_batch(changed)


def test_ray_missing_says_how_to_install(tmp_path, capsys, monkeypatch):
    from intuitf.cli.app import main

    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails as if not installed
    with pytest.raises(SystemExit) as exc:
        main(["batch", "ref.png", "vols", "--ray", "-o", str(tmp_path / "o")])
    assert exc.value.code == 2
    err = " ".join(capsys.readouterr().err.split())  # rich wraps long lines
    assert "pip install" in err and "intuitf[ray]" in err and "Traceback" not in err


# -- the fake model server ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def server(batch_inputs):
    with FakeMLLMServer(target=load_image(batch_inputs["picture"]), latency=0.02) as srv:
        yield srv


@pytest.fixture(scope="module")
def straight(batch_inputs, server, tmp_path_factory):
    """The batch run once, uninterrupted, on the pool: what every other way must reproduce."""
    root = tmp_path_factory.mktemp("straight") / "out"
    before = server.stats.requests
    summary = run_batch(_request(batch_inputs, root, evaluator=server.base_url))
    assert set(_statuses(summary).values()) == {"completed"}
    return {"root": root, "bests": _bests(root), "requests": server.stats.requests - before,
            "summary": summary}  # fmt: skip


@pytest.mark.slow
def test_budget_holds_across_workers_and_a_larger_one_finishes_the_same(
    batch_inputs, server, straight, tmp_path
):
    root = tmp_path / "out"
    limit = straight["requests"] // 3
    before = server.stats.requests
    first = run_batch(_request(batch_inputs, root, evaluator=server.base_url, budget_calls=limit))
    sent = server.stats.requests - before
    # The budget is reserved before each request: never more requests than the limit.
    assert sent <= limit
    assert first["budget"]["paid_calls"] + first["budget"]["in_flight"] <= limit
    assert "budget" in _statuses(first).values()
    assert first["totals"]["calls"] == sent  # the runs' own stores agree with the server

    asked = server.stats.requests
    answered = _answers(root)
    second = run_batch(
        _request(batch_inputs, root, evaluator=server.base_url, budget_calls=10 * limit)
    )
    assert set(_statuses(second).values()) == {"completed"}
    # Nothing paid for was asked again, and the results are those of the straight run.
    assert server.stats.requests - asked == straight["requests"] - answered
    assert _bests(root) == straight["bests"]


@pytest.mark.slow
def test_killed_batch_resumes_with_no_paid_call_repeated(
    batch_inputs, server, straight, tiny, tmp_path
):
    root = tmp_path / "out"
    cmd = [sys.executable, "-m", "intuitf", "batch", str(batch_inputs["tf"]),
           str(batch_inputs["vols"]), "--reference-volume", str(batch_inputs["ref_volume"]),
           "--evaluator", server.base_url, "--max-dim", "32", "--workers", "2",
           "--per-worker", "2", "-o", str(root), *tiny["args"]]  # fmt: skip
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    wait_for(lambda: list((root / "runs").glob("*/checkpoint.json")), timeout=240,
             what="a finished generation")  # fmt: skip
    # Into the middle of the next generations: more questions asked since that checkpoint.
    asked = server.stats.requests
    wait_for(lambda: server.stats.requests > asked, timeout=60, what="the next question")
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert list((root / "runs").glob("*/checkpoint.json")), "no generation finished before the kill"
    # The workers die with the batch, and their run folders' locks go with them.
    for folder in (root / "runs").iterdir():
        if folder.is_dir():
            wait_for(lambda f=folder: not in_use(f), timeout=60, what=f"{folder}'s lock")
    asked = server.stats.requests
    answered = _answers(root)

    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    assert server.stats.requests - asked == straight["requests"] - answered
    assert _bests(root) == straight["bests"]
    summary = json.loads((root / "summary.json").read_text())
    assert summary["totals"]["completed"] == len(straight["bests"])


@pytest.mark.slow
def test_local_ray_gives_the_same_results_stopped_or_not(batch_inputs, server, straight, tmp_path):
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        root = tmp_path / "ray"
        req = _request(batch_inputs, root, evaluator=server.base_url, ray="local")
        before = server.stats.requests
        summary = run_batch(req)
        assert summary["backend"] == "ray"
        assert set(_statuses(summary).values()) == {"completed"}
        assert _bests(root) == straight["bests"]
        assert server.stats.requests - before == straight["requests"]  # the same questions

        # Stopped part way (like Ctrl-C: runs cancelled between matches), then resumed.
        root2 = tmp_path / "ray-stopped"
        req2 = _request(batch_inputs, root2, evaluator=server.base_url, ray="local")

        def one_generation_done() -> bool:
            return any((root2 / "runs").glob("*/checkpoint.json"))

        # Slower answers (the same answers) leave time to stop before the runs finish, also
        # on a loaded machine.
        fast = server.latency
        server.latency = Latency.parse(0.25)
        try:
            stopped = run_batch(req2, stop_when=one_generation_done)
        finally:
            server.latency = fast
        assert set(_statuses(stopped).values()) != {"completed"}
        assert ray.is_initialized()  # a Ray instance the batch did not start is left running
        asked, answered = server.stats.requests, _answers(root2)
        resumed = run_batch(req2)
        assert set(_statuses(resumed).values()) == {"completed"}
        assert server.stats.requests - asked == straight["requests"] - answered
        assert _bests(root2) == straight["bests"]
        assert len(stopped["volumes"]) == len(resumed["volumes"])
    finally:
        ray.shutdown()
