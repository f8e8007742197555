"""Tournament cost and ranking quality: the authors' protocol against intuitf's efficient one.

Both run the real ``MLLMJudge`` over loopback HTTP against the fake model server
(``intuitf.testing.fake_mllm``), whose oracle prefers the image closer to a hidden target, with
latency, 10 % noise and 20 % position bias. A population of 50 synthetic images (blends of the
target with noise images, so each one's true quality is known) evolves over several
generations: the top fifth *by the protocol's own ranking* survives unchanged, the rest are new
blends near the survivors (a slowly improving population, as in a real run).

Protocols:

- ``authors``: ratings reset every generation, ``floor(log2 n) + 2`` = 7 rounds (175 pairs at
  n = 50), every pair asked in both orders (``swap="always"``), no verdict cache.
- ``efficient``: as a Session runs it: ``SwissTournament(protocol="efficient")`` (Bradley-Terry
  ranking and pairing, surprising verdicts re-asked in the other order),
  ``MLLMJudge(swap="never")`` (one call per pair, orientation drawn by the tournament), a
  verdict cache, the survivors' ratings passed as ``prior`` (they seed the first round's
  pairing) and the earlier generations' verdicts as ``history``, faded by ``HISTORY_FADE`` per
  generation of age.
- only with ``--variants``: ``paper+auto``, the authors' schedule with single-call judging (to
  separate the effect of swap debiasing from the effect of priors and the Bradley-Terry fit);
  ``eff-full``, the efficient protocol with the history at full weight; ``eff-nohist``, without
  history.

Printed per protocol: paid model calls per generation, cache hits, wall time per tournament,
its ratio to ``rounds × latency``, Kendall's τ of the final ratings against the oracle's true
order (scipy.stats.kendalltau), the share of the true top ten among the ranking's top ten, and
``best``: the share of generations whose first-ranked image is the truly best one (the pick a
run shows as its best), averaged over generations and repeats.

Usage: ``python benchmarks/tournament.py`` (latency 2 s and 0.5 s, about 5 minutes) or
``--quick`` (latency 0.5 s only, about a minute). Also prints the MetricJudge's time per
comparison at 256 x 256.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import math
import socket
import subprocess
import sys
import tempfile
import time
import types
from dataclasses import dataclass, field
from pathlib import Path

import httpx
import numpy as np
from PIL import Image
from scipy.stats import kendalltau

from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.ratings import HISTORY_FADE
from intuitf.evaluator.tournament import SwissTournament
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer, TargetOracle

SIZE = 64
POP = 50
SURVIVE = 10


def smooth_image(rng: np.random.Generator) -> np.ndarray:
    """A random smooth colour image (low-frequency noise), uint8 SIZE x SIZE x 3."""
    coarse = rng.random((6, 6, 3))
    idx = np.linspace(0, 5, SIZE)
    i0 = np.floor(idx).astype(int).clip(0, 4)
    t = (idx - i0)[:, None]
    rows = coarse[i0] * (1 - t[..., None]) + coarse[i0 + 1] * t[..., None]
    cols = rows[:, i0] * (1 - t[None, :, :]) + rows[:, i0 + 1] * t[None, :, :]
    return (cols * 255).astype(np.uint8)


@dataclass
class Candidate:
    cid: str
    weight: float  # blend weight of the target (1 = the target itself)
    image: np.ndarray


class Population:
    """Blends of a target with noise images; new ones are drawn near the survivors."""

    def __init__(self, target: np.ndarray, seed: int) -> None:
        self.target = target.astype(np.float32)
        self.rng = np.random.default_rng(seed)
        self.counter = 0

    def new(self, weight: float) -> Candidate:
        w = float(np.clip(weight, 0.0, 0.97))
        noise = smooth_image(self.rng).astype(np.float32)
        img = (w * self.target + (1 - w) * noise).round().astype(np.uint8)
        self.counter += 1
        return Candidate(f"c{self.counter}", w, img)

    def initial(self) -> list[Candidate]:
        return [self.new(self.rng.uniform(0.0, 0.6)) for _ in range(POP)]

    def next(self, survivors: list[Candidate]) -> list[Candidate]:
        children = []
        for _ in range(POP - len(survivors)):
            parent = survivors[int(self.rng.integers(len(survivors)))]
            children.append(self.new(parent.weight + self.rng.normal(0.0, 0.12)))
        return survivors + children


@dataclass
class Tally:
    calls: list[int] = field(default_factory=list)
    cached: list[int] = field(default_factory=list)
    wall: list[float] = field(default_factory=list)
    ratio: list[float] = field(default_factory=list)
    rounds: list[int] = field(default_factory=list)
    tau: list[float] = field(default_factory=list)
    top_hit: list[float] = field(default_factory=list)
    best_hit: list[float] = field(default_factory=list)


async def run_protocol(
    name: str, base_url: str, latency: float, generations: int, seed: int, oracle: TargetOracle,
    target: np.ndarray,
) -> Tally:  # fmt: skip
    aspects = aspects_for("quality")
    if name == "authors":
        judge = MLLMJudge(base_url=base_url, swap="always", max_concurrency=64, max_retries=2)
        protocol, rounds, cache = "paper", int(math.floor(math.log2(POP))) + 2, None
    elif name == "paper+auto":
        judge = MLLMJudge(base_url=base_url, swap="auto", max_concurrency=64, max_retries=2)
        protocol, rounds, cache = "paper", int(math.floor(math.log2(POP))) + 2, None
    else:  # efficient, eff-full, eff-nohist
        cache = VerdictCache(":memory:")
        judge = MLLMJudge(
            base_url=base_url, swap="never", max_concurrency=64, max_retries=2, cache=cache
        )
        protocol, rounds = "efficient", None
    pop = Population(target, seed)
    cands = pop.initial()
    prior: dict[str, float] | None = None
    fade = {"efficient": HISTORY_FADE, "eff-full": 1.0}.get(name)
    played: list[tuple[str, str, float, int]] = []  # (first, second, score, generation)
    tally = Tally()
    for gen in range(generations):
        t = SwissTournament(judge, aspects, Intent(), seed=seed * 100 + gen, protocol=protocol,
                            rounds=rounds)  # fmt: skip
        history = [(a, b, sc, fade ** (gen - g)) for a, b, sc, g in played] if fade else []
        res = await t.run(
            [c.image for c in cands], [c.cid for c in cands], prior=prior, history=history
        )
        played += [(m.first, m.second, float(m.verdict.p_first), gen) for m in res.matches]
        truth = {c.cid: oracle(c.image) for c in cands}
        tally.calls.append(res.cost.calls)
        tally.cached.append(res.cost.cached_calls)
        tally.wall.append(res.wall_seconds)
        tally.rounds.append(res.rounds)
        tally.ratio.append(res.wall_seconds / (res.rounds * latency))
        ids = [c.cid for c in cands]
        tally.tau.append(
            kendalltau([res.ratings[i] for i in ids], [truth[i] for i in ids]).statistic
        )
        true_order = sorted(ids, key=lambda i: -truth[i])
        tally.top_hit.append(len(set(true_order[:SURVIVE]) & set(res.ranking[:SURVIVE])) / SURVIVE)
        tally.best_hit.append(float(res.ranking[0] == true_order[0]))
        by_id = {c.cid: c for c in cands}
        survivors = [by_id[i] for i in res.ranking[:SURVIVE]]
        prior = (
            {i: res.ratings[i] for i in res.ranking[:SURVIVE]} if protocol == "efficient" else None
        )
        if protocol != "efficient":
            played.clear()
        cands = pop.next(survivors)
    await judge.aclose()
    return tally


def metric_timing() -> tuple[float, float]:
    """MetricJudge ms per comparison at 256 x 256: first sight of both images, and cached."""
    rng = np.random.default_rng(0)
    imgs = []
    for _ in range(24):
        img = np.zeros((256, 256, 3), np.uint8)
        yy, xx = np.mgrid[0:256, 0:256]
        mask = (xx - 128) ** 2 + (yy - 128) ** 2 < rng.integers(40, 120) ** 2
        img[mask] = (rng.random((int(mask.sum()), 3)) * 255).astype(np.uint8)
        imgs.append(img)
    aspects = aspects_for("quality")
    judge = MetricJudge()
    t0 = time.perf_counter()
    for i in range(0, 24, 2):
        judge.compare_sync(imgs[i], imgs[i + 1], aspects, Intent())
    cold = (time.perf_counter() - t0) / 12 * 1e3
    t0 = time.perf_counter()
    for i in range(200):
        judge.compare_sync(imgs[i % 24], imgs[(i * 7 + 3) % 24], aspects, Intent())
    warm = (time.perf_counter() - t0) / 200 * 1e3
    return cold, warm


@contextlib.contextmanager
def in_process_server(target: np.ndarray, latency: float):
    with FakeMLLMServer(
        target=target, latency=latency, noise=0.10, position_bias=0.20, seed=7
    ) as server:
        yield server


@contextlib.contextmanager
def external_server(target: np.ndarray, latency: float):
    """``python -m intuitf.testing.fake_mllm`` in a subprocess on a free loopback port."""
    with tempfile.TemporaryDirectory() as tmp:
        target_path = Path(tmp) / "target.png"
        Image.fromarray(target).save(target_path)
        with socket.socket() as sock:
            sock.bind(("127.0.0.1", 0))
            port = sock.getsockname()[1]
        cmd = [sys.executable, "-m", "intuitf.testing.fake_mllm", "--port", str(port),
               "--target", str(target_path), "--latency", str(latency), "--noise", "0.1",
               "--position-bias", "0.2", "--seed", "7"]  # fmt: skip
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        base_url = f"http://127.0.0.1:{port}/v1"
        try:
            deadline = time.time() + 60
            while True:
                try:
                    httpx.get(f"{base_url}/models", timeout=1.0).raise_for_status()
                    break
                except httpx.HTTPError:
                    if time.time() > deadline or proc.poll() is not None:
                        raise RuntimeError("the fake model server did not start") from None
                    time.sleep(0.2)
            yield types.SimpleNamespace(base_url=base_url)
        finally:
            proc.terminate()
            proc.wait(timeout=10)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="latency 0.5 s only")
    ap.add_argument("--generations", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=None, help="seeds per setting")
    ap.add_argument(
        "--variants", action="store_true", help="also run paper+auto, eff-full, eff-nohist"
    )
    ap.add_argument(
        "--server-process",
        action="store_true",
        help="run the fake model server in its own process (as a real server would be), so "
        "its image decoding does not share this process's interpreter",
    )
    args = ap.parse_args()
    latencies = [0.5] if args.quick else [2.0, 0.5]
    variants = ["paper+auto", "eff-full", "eff-nohist"]
    protocols = ["authors", "efficient"] + (variants if args.variants else [])

    cold, warm = metric_timing()
    print(f"MetricJudge at 256x256: {cold:.1f} ms per comparison of new images, "
          f"{warm:.2f} ms with cached features")  # fmt: skip
    print(f"population {POP}, survivors {SURVIVE}, {args.generations} generations, "
          "noise 10 %, position bias 20 %")  # fmt: skip
    header = (f"{'latency':>7} {'protocol':<11} {'calls/gen':>9} {'cached/gen':>10} "
              f"{'rounds':>6} {'wall s':>7} {'wall/(r*lat)':>12} {'tau':>6} {'top10':>6} "
              f"{'best':>5}")  # fmt: skip
    rng = np.random.default_rng(12345)
    target = smooth_image(rng)
    oracle = TargetOracle(target)
    rows = []
    for latency in latencies:
        repeats = args.repeats or (2 if latency < 1 else 1)
        serve = external_server if args.server_process else in_process_server
        with serve(target, latency) as server:
            for proto in protocols:
                tallies = [
                    asyncio.run(
                        run_protocol(
                            proto,
                            server.base_url,
                            latency,
                            args.generations,
                            seed=r + 1,
                            oracle=oracle,
                            target=target,
                        )
                    )  # fmt: skip
                    for r in range(repeats)
                ]
                agg = Tally()
                for tl in tallies:
                    for k in agg.__dict__:
                        getattr(agg, k).extend(getattr(tl, k))
                rows.append((latency, proto, agg))
    print(header)
    base: dict[float, Tally] = {}
    for latency, proto, agg in rows:
        if proto == "authors":
            base[latency] = agg
        print(
            f"{latency:>7.1f} {proto:<11} {np.mean(agg.calls):>9.1f} {np.mean(agg.cached):>10.1f} "
            f"{np.mean(agg.rounds):>6.1f} {np.mean(agg.wall):>7.2f} {np.mean(agg.ratio):>12.2f} "
            f"{np.mean(agg.tau):>6.3f} {np.mean(agg.top_hit):>6.2f} {np.mean(agg.best_hit):>5.2f}"
        )
    for latency, proto, agg in rows:
        if proto != "authors" and latency in base:
            saved = 1 - np.mean(agg.calls) / np.mean(base[latency].calls)
            dtau = np.mean(agg.tau) - np.mean(base[latency].tau)
            print(f"latency {latency}: {proto} uses {saved:.0%} fewer paid calls than the "
                  f"authors' protocol, Kendall tau {dtau:+.3f}")  # fmt: skip
    per_gen = "; ".join(
        f"{proto}@{lat}: tau per gen {np.round(agg.tau, 2).tolist()}" for lat, proto, agg in rows
    )
    print(per_gen)


if __name__ == "__main__":
    main()
