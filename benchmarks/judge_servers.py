"""The model judge against servers that behave like the ones people use (fake personalities).

**Short runs.** For each personality of the fake model server (an OpenAI reasoning model, by its
preset and by a bare URL; a Gemini thinking model on a low requests-per-minute tier; a one-slot
Ollama; LM Studio; a one-image vLLM), a short ``intuitf optimize`` (population 8, 2 generations,
64-pixel judging images) with the fake server as base URL: model calls, requests the server
rejected (and why), matches asked again, undecided matches and wall time. The issue's target:
every run completes with at most 5 % undecided matches.

**A one-slot server that is slow.** 16 comparisons at once against a server that works on one
request at a time, ``--answer`` seconds per answer, with a request timeout of ``--timeout``
seconds: how many got an answer, and how many requests the server saw. (The judge before the
profiles sent 16 at once and lost most of them to timeouts: 2 of 16 answered at 1 s per answer
and a 3 s timeout on the machine where this was written.)

    python benchmarks/judge_servers.py                  # both parts (about two minutes)
    python benchmarks/judge_servers.py --part slow --answer 1 --timeout 3

Figures depend on the machine and on what else runs on it.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing import images, personalities
from intuitf.testing.fake_mllm import FakeMLLMServer, Personality
from intuitf.testing.images import red_disc


def short_run(personality: str, folder: Path) -> dict:
    """One short optimize against ``personality``: the figures of the issue's note."""
    with FakeMLLMServer(target=red_disc(), personality=personalities.served(personality)) as srv:
        spec = personalities.optimize_flags(personality, srv.base_url)
        env = dict(os.environ, OPENAI_API_KEY="sk-fake", GEMINI_API_KEY="fake")
        run = folder / personality
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "intuitf", "optimize", "phantom", *spec,
             "--population", "8", "--generations", "2", "--size", "64", "--output-size", "64",
             "--top", "1", "--seed", "1", "--text", "red bone", "-o", str(run)],
            capture_output=True, text=True, env=env,
        )  # fmt: skip
        wall = time.perf_counter() - t0
    matches = undecided = retried = 0
    if (run / "journal.jsonl").exists():
        for line in (run / "journal.jsonl").read_text().splitlines():
            e = json.loads(line)
            stats = (e.get("match_stats") or {}) if e.get("type") == "generation" else {}
            matches += stats.get("matches", 0)
            undecided += stats.get("undecided", 0)
            retried += stats.get("retried", 0)
    record = json.loads((run / "run.json").read_text()) if (run / "run.json").exists() else {}
    return {
        "personality": personality,
        "exit": proc.returncode,
        "calls": srv.stats.answered,
        "requests": srv.stats.requests,
        "rejected": dict(srv.stats.rejected),
        "re-asked": retried,
        "follow-ups": srv.stats.follow_ups,
        "undecided": f"{undecided}/{matches}",
        "wall_s": round(wall, 1),
        "adapted": [a["what"] for a in record.get("judge_adaptations", [])],
    }


def slow_one_slot(answer_s: float, timeout_s: float, n: int = 16) -> dict:
    """``n`` comparisons at once against a one-slot server, with the default judge."""
    target, c = images.oracle_images()
    one = Personality("one-slot", models=("qwen2.5vl:7b",), slots=1, latency=answer_s)
    with FakeMLLMServer(target=target, personality=one) as srv:
        judge = MLLMJudge(
            "qwen2.5vl:7b",
            provider="ollama",
            base_url=srv.base_url,
            swap="never",
            timeout=timeout_s,
            deadline=2 * timeout_s,
        )

        async def run() -> list:
            q = aspects_for("quality")
            jobs = (judge.compare(c[i % 8], c[(i + 1) % 8], q, Intent()) for i in range(n))
            return await asyncio.gather(*jobs, return_exceptions=True)

        t0 = time.perf_counter()
        out = asyncio.run(run())
        wall = time.perf_counter() - t0
    failed = sum(isinstance(o, BaseException) for o in out)
    return {
        "answered": f"{n - failed}/{n}",
        "requests": srv.stats.requests,
        "max_in_flight": srv.stats.max_in_flight,
        "wall_s": round(wall, 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", choices=("runs", "slow", "both"), default="both")
    ap.add_argument("--answer", type=float, default=1.0, help="seconds per answer (slow part)")
    ap.add_argument("--timeout", type=float, default=3.0, help="request timeout (slow part)")
    args = ap.parse_args()
    if args.part in ("runs", "both"):
        print("Short optimize runs (population 8, 2 generations):")
        with tempfile.TemporaryDirectory() as tmp:
            for name in personalities.SPECS:
                print("  " + json.dumps(short_run(name, Path(tmp))), flush=True)
    if args.part in ("slow", "both"):
        print(
            f"One-slot server, {args.answer:g} s per answer, {args.timeout:g} s timeout, 16 at once:"
        )
        print("  " + json.dumps(slow_one_slot(args.answer, args.timeout)))


if __name__ == "__main__":
    main()
