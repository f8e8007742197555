"""Faults at batch scale: a failed volume goes again (--max-failures), an unreachable Ray address
fails fast with a clear message, and a resume runs where the batch was started."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time

import pytest

from intuitf.batch import runner
from intuitf.batch.plan import VolumeItem
from intuitf.batch.runner import BatchConfig, drive


class _ScriptedBackend:
    """A backend whose volumes end as ``script[key]`` says, one status per try."""

    name = "scripted"

    def __init__(self, script: dict[str, list[str]]) -> None:
        self.script = {k: list(v) for k, v in script.items()}
        self.workers = 1
        self.tries: dict[str, int] = {}
        self._out: list[tuple[int, dict]] = []

    def __call__(self, config, workers):  # stands in for PoolBackend(config, workers)
        return self

    def alive(self, w: int) -> bool:
        return True

    def submit(self, w: int, item: VolumeItem) -> None:
        self.tries[item.key] = self.tries.get(item.key, 0) + 1
        status = self.script[item.key].pop(0)
        self._out.append((w, {"key": item.key, "status": status, "message": f"try {status}"}))

    def poll(self, timeout: float):
        out, self._out = self._out, []
        if not out:
            time.sleep(0.01)
        return out

    def stop(self) -> None:
        pass

    def shutdown(self, wait: float = 30.0) -> None:
        pass


def test_a_failed_volume_goes_again_up_to_max_failures(tmp_path, monkeypatch):
    backend = _ScriptedBackend(
        {
            "a": ["judge", "completed"],  # the judge came back: done on the second try
            "b": ["failed", "judge", "judge"],  # fails every try: reported after 1 + 2
            "c": ["completed"],
            "d": ["budget"],  # the budget is not a failure to retry
        }
    )
    monkeypatch.setattr(runner, "PoolBackend", backend)
    monkeypatch.setattr(runner, "RETRY_WAIT_S", 0.0)
    items = [VolumeItem(k, f"/v/{k}.npy", k) for k in "abcd"]
    events: list[tuple[str, str]] = []
    results = drive(
        BatchConfig(root=str(tmp_path), template={}),
        items,
        workers=1,
        max_failures=2,
        on_update=lambda ev, it, res: events.append((ev, it.key)),
    )
    assert backend.tries == {"a": 2, "b": 3, "c": 1, "d": 1}
    assert {k: r["status"] for k, r in results.items()} == {
        "a": "completed", "b": "judge", "c": "completed", "d": "budget"
    }  # fmt: skip
    assert results["b"]["retries"] == 2 and results["a"]["retries"] == 1
    assert events.count(("retry", "b")) == 2 and events.count(("done", "b")) == 1
    assert json.loads((tmp_path / "results" / "b.json").read_text())["retries"] == 2


def test_no_retry_when_max_failures_is_zero(tmp_path, monkeypatch):
    backend = _ScriptedBackend({"a": ["judge", "completed"]})
    monkeypatch.setattr(runner, "PoolBackend", backend)
    results = drive(BatchConfig(root=str(tmp_path), template={}),
                    [VolumeItem("a", "/v/a.npy", "a")], workers=1, max_failures=0)  # fmt: skip
    assert backend.tries == {"a": 1} and results["a"]["status"] == "judge"


# -- Ray: addresses that do not answer ------------------------------------------------------
def _batch(args: list[str], tmp_path, timeout: float = 120) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "intuitf", "batch", "ref.png", "vol.npy", "-o",
           str(tmp_path / "out"), *args]  # fmt: skip
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=tmp_path)


@pytest.fixture
def inputs(batch_inputs, tmp_path):
    (tmp_path / "ref.png").symlink_to(batch_inputs["picture"])
    (tmp_path / "vol.npy").symlink_to(next(batch_inputs["vols"].glob("*32*.npy")))
    return tmp_path


@pytest.mark.parametrize("address", ["127.0.0.1:1", "nohost.invalid:6379"])
def test_an_unreachable_ray_address_fails_at_once_and_says_so(inputs, address):
    pytest.importorskip("ray")
    t0 = time.monotonic()
    done = _batch(["--ray", address], inputs)
    assert time.monotonic() - t0 < 60  # not the forever of before
    assert done.returncode != 0
    assert f"Cannot reach a Ray cluster at {address}" in done.stderr + done.stdout
    assert "Traceback" not in done.stderr


def test_a_ray_head_that_never_answers_times_out(inputs):
    """Something listens at the address but never speaks Ray: --ray-timeout ends the wait."""
    pytest.importorskip("ray")
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(16)
    port = listener.getsockname()[1]
    held: list[socket.socket] = []

    def accept() -> None:  # take connections and say nothing
        while True:
            try:
                held.append(listener.accept()[0])
            except OSError:
                return

    threading.Thread(target=accept, daemon=True).start()
    try:
        t0 = time.monotonic()
        done = _batch(["--ray", f"127.0.0.1:{port}", "--ray-timeout", "4"], inputs, timeout=90)
        took = time.monotonic() - t0
    finally:
        listener.close()
        for c in held:
            c.close()
    out = done.stderr + done.stdout
    assert done.returncode != 0, out
    assert f"Ray at 127.0.0.1:{port} did not answer within 4 s" in out, out
    assert took < 60


# -- accounting across passes -----------------------------------------------------------------
def test_a_rerun_that_finds_the_budget_spent_keeps_the_figures(batch_inputs, tmp_path):
    from intuitf.batch import BatchRequest, run_batch
    from intuitf.imageio import load_image
    from intuitf.testing.fake_mllm import FakeMLLMServer

    vols = sorted(str(p) for p in batch_inputs["vols"].glob("phantom*.npy"))[:2]
    settings = dict(population=6, generations=2, image_size=32, output_size=48, top_k=1,
                    seed=1, stages=[["customize", 2]])  # fmt: skip
    with FakeMLLMServer(target=load_image(batch_inputs["picture"]), latency=0.01) as srv:
        req = BatchRequest(root=str(tmp_path / "b"), reference=str(batch_inputs["picture"]),
                           volumes=vols, settings=settings, reader={"max_dim": 32}, workers=1,
                           per_worker=2, evaluator=srv.base_url, budget_calls=12)  # fmt: skip
        first = run_batch(req)
        assert "budget" in {v["status"] for v in first["volumes"]}
        again = run_batch(req)  # the same budget, already spent
        sent = srv.stats.requests
    assert again["totals"]["calls"] == first["totals"]["calls"] == sent > 0
    figures = {v["key"]: (v["calls"], v["generations_done"]) for v in first["volumes"]}
    assert {v["key"]: (v["calls"], v["generations_done"]) for v in again["volumes"]} == figures


# -- the batch report ---------------------------------------------------------------------------
def test_the_batch_report_is_self_contained_with_undecided_figures(batch_inputs, tmp_path):
    import re

    from intuitf.batch.plan import VolumeItem
    from intuitf.batch.runner import write_result
    from intuitf.batch.summary import build_summary, write_summary
    from intuitf.imageio import load_image, save_png

    root = tmp_path / "batch"
    picture = load_image(batch_inputs["picture"])
    save_png(picture, root / "reference" / "reference.png")
    items = []
    for i, (undecided, matches) in enumerate(((0, 40), (9, 30))):
        key = f"a-rather-long-volume-name-{i}"
        save_png(picture, root / "runs" / key / "best" / "rank01.png")
        write_result(root, {"key": key, "label": key, "source": f"/v/{key}.npy",
                            "status": "completed", "similarity": 0.9 - i / 2, "calls": 50,
                            "matches": matches, "undecided": undecided,
                            "indistinct_generations": [1] if i else [],
                            "best_png": f"runs/{key}/best/rank01.png", "run_dir": "x"})  # fmt: skip
        items.append(VolumeItem(key, f"/v/{key}.npy", key))
    summary = build_summary(root, items, {})
    assert summary["totals"]["undecided"] == 9 and summary["totals"]["matches"] == 70
    paths = write_summary(root, summary)
    page = paths["report"].read_text()
    srcs = re.findall(r'<img src="([^"]*)"', page)
    assert len(srcs) == 4  # the reference, two bests, the contact sheet
    assert all(s.startswith("data:image/png;base64,") for s in srcs)
    assert "9 of 30 (30 %)" in page and "9 of 70 matches (13 %)" in page
    assert "generation 1: the judge could not tell the candidates apart" in page
    sheet = load_image(paths["contact_sheet"])
    assert sheet.shape[1] >= 3 * 320  # three tiles of 320 pixels side by side


def test_a_ray_client_address_without_the_client_says_what_to_install(monkeypatch):
    from intuitf.errors import IntuitfError

    monkeypatch.setitem(sys.modules, "grpc", None)  # as if ray[client] were not installed
    with pytest.raises(IntuitfError) as info:
        runner._check_reachable("ray://127.0.0.1:10001", 5.0)
    assert "ray[client]" in str(info.value) or "intuitf[ray]" in str(info.value)


def test_a_ray_client_address_that_does_not_answer_fails_at_once():
    pytest.importorskip("grpc")
    from intuitf.errors import IntuitfError

    with pytest.raises(IntuitfError, match="Cannot reach a Ray cluster at ray://127.0.0.1:1"):
        runner._check_reachable("ray://127.0.0.1:1", 5.0)
