"""A short `intuitf optimize` completes against every fake server personality: an OpenAI
reasoning model, a Gemini thinking model on a low requests-per-minute tier, a one-slot local
server (Ollama), a server that needs the loaded model's id (LM Studio) and a one-image server
(older vLLM), with at most 5 % undecided matches.

The first requests each personality received (images shortened) are kept under
tests/data/judge_requests/ as a record of what intuitf sends; the test checks that what it
sends now matches them. ``INTUITF_RECORD_REQUESTS=1`` writes them anew.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from intuitf.testing import personalities
from intuitf.testing.fake_mllm import FakeMLLMServer
from intuitf.testing.images import red_disc

FIXTURES = Path(__file__).parent.parent / "data" / "judge_requests"


def _shape(body: dict) -> dict:
    """What a request says apart from its wording: parameters, roles, part types and labels."""
    out = {k: v for k, v in body.items() if k not in ("messages", "response_format")}
    rf = body.get("response_format")
    out["response_format"] = rf.get("type") if isinstance(rf, dict) else None
    out["messages"] = [
        [m["role"]]
        + (
            [
                p["type"] + (":" + p["text"][:12] if p["type"] == "text" else "")
                for p in m["content"]
            ]
            if isinstance(m["content"], list)
            else ["text"]
        )
        for m in body["messages"]
    ]
    return out


def _run(
    personality: str, run: Path, *extra: str
) -> tuple[subprocess.CompletedProcess, FakeMLLMServer, float]:
    served = personalities.served(personality)
    with FakeMLLMServer(target=red_disc(), personality=served) as srv:
        spec = personalities.optimize_flags(personality, srv.base_url)
        env = dict(
            os.environ, OPENAI_API_KEY="sk-fake", GEMINI_API_KEY="fake", PYTHONUNBUFFERED="1"
        )
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "intuitf", "optimize", "phantom", *spec,
             "--population", "8", "--generations", "2", "--size", "64", "--output-size", "64",
             "--top", "1", "--seed", "1", "--text", "red bone", "-o", str(run), *extra],
            capture_output=True, text=True, env=env, timeout=300,
        )  # fmt: skip
        return proc, srv, time.perf_counter() - t0


def _matches(run: Path) -> tuple[int, int, int]:
    """(matches, undecided, asked again) over the run's generations, from its journal."""
    total = undecided = retried = 0
    for line in (run / "journal.jsonl").read_text().splitlines():
        e = json.loads(line)
        if e.get("type") == "generation":
            stats = e.get("match_stats") or {}
            total += stats.get("matches", 0)
            undecided += stats.get("undecided", 0)
            retried += stats.get("retried", 0)
    return total, undecided, retried


@pytest.mark.slow
@pytest.mark.parametrize("personality", list(personalities.SPECS))
def test_short_optimize_completes_against_each_personality(personality, tmp_path):
    run = tmp_path / "run"
    proc, srv, wall = _run(personality, run)
    assert proc.returncode == 0, (proc.stdout[-2000:], proc.stderr[-3000:])
    assert "Traceback" not in proc.stderr
    total, undecided, retried = _matches(run)
    assert total > 0 and undecided <= 0.05 * total, (total, undecided)
    record = json.loads((run / "run.json").read_text())
    # The figures of the note, printed for `pytest -s`.
    print(
        f"\n{personality}: {srv.stats.answered} calls ({srv.stats.requests} requests, rejected "
        f"{srv.stats.rejected}), {retried} re-asked, {undecided}/{total} undecided, "
        f"{wall:.1f} s, adaptations {[a['what'] for a in record.get('judge_adaptations', [])]}"
    )
    if personality == "vllm-one-image":
        assert [a["what"] for a in record["judge_adaptations"]] == ["images per request"]
    if personality == "openai-reasoning-by-url":
        assert [a["what"] for a in record["judge_adaptations"]] == ["max_tokens"]
    if personality == "gemini-thinking-small-budget":
        assert srv.stats.empty_answers > 0 and "empty parts" not in srv.stats.rejected
        assert retried > 0  # matches whose first answer was empty were asked again
    if personality in ("ollama", "lmstudio"):
        assert srv.stats.max_in_flight <= 4  # a one-slot server is not flooded
    first = srv.requests_log[:3]
    fixture = FIXTURES / f"{personality}.json"
    if os.environ.get("INTUITF_RECORD_REQUESTS"):
        fixture.parent.mkdir(parents=True, exist_ok=True)
        fixture.write_text(json.dumps(first, indent=1) + "\n")
    recorded = json.loads(fixture.read_text())
    assert _shape(first[0]) == _shape(recorded[0])


@pytest.mark.slow
def test_max_concurrency_option_holds_the_judge_to_it(tmp_path):
    run = tmp_path / "run"
    proc, srv, _ = _run("vllm-one-image", run, "--max-concurrency", "1")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert srv.stats.max_in_flight == 1
    record = json.loads((run / "run.json").read_text())
    assert record["spec"]["judge"]["options"]["max_concurrency"] == 1
