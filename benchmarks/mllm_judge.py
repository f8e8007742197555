"""Throughput of MLLMJudge against the fake model server over loopback HTTP.

Prints, for a burst of comparisons at a given server latency: wall time, requests, the server's
maximum in-flight count, and the time to answer the same burst again from the verdict cache.

    python benchmarks/mllm_judge.py --pairs 50 --latency 2 --concurrency 32
"""

from __future__ import annotations

import argparse
import asyncio
import time

import numpy as np

from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.mllm import MLLMJudge
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for
from intuitf.testing.fake_mllm import FakeMLLMServer


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=50)
    ap.add_argument("--latency", type=float, default=2.0)
    ap.add_argument("--concurrency", type=int, default=32)
    ap.add_argument("--swap", default="always", choices=["always", "never", "auto"])
    ap.add_argument("--size", type=int, default=512, help="image side in pixels")
    ap.add_argument("--format", default="png", choices=["png", "jpeg"])
    args = ap.parse_args()

    # Rendering-like pictures: a shaded disc on a flat background (noise images would measure
    # the PNG encoder's worst case instead); candidates differ by a colour shift.
    n = args.size
    yy, xx = np.mgrid[0:n, 0:n] / n
    r = np.hypot(yy - 0.5, xx - 0.5)
    disc = (r < 0.35)[..., None]
    shade = np.stack([1 - r, 0.6 + 0.4 * xx, 0.3 + 0.5 * yy], -1) * 255
    target = np.where(disc, shade, 255).astype(np.uint8)
    images = [
        np.where(disc, np.clip(shade + [3 * k, -2 * k, k], 0, 255), 255).astype(np.uint8)
        for k in range(1, 2 * args.pairs + 1)
    ]
    pairs = [(images[i], images[(i + 1) % len(images)]) for i in range(args.pairs)]
    aspects = aspects_for("quality")

    async def burst(judge: MLLMJudge) -> float:
        t0 = time.perf_counter()
        await asyncio.gather(*(judge.compare(a, b, aspects, Intent()) for a, b in pairs))
        return time.perf_counter() - t0

    with FakeMLLMServer(target=target, latency=args.latency) as srv:
        judge = MLLMJudge(
            "default",
            base_url=srv.base_url,
            swap=args.swap,
            max_concurrency=args.concurrency,
            image_format=args.format,
            timeout=args.latency * 5 + 30,
            cache=VerdictCache(":memory:"),
        )
        cold = asyncio.run(burst(judge))
        requests, peak = srv.stats.requests, srv.stats.max_in_flight
        warm = asyncio.run(burst(judge))
    ideal = np.ceil(requests / args.concurrency) * args.latency
    print(
        f"{args.pairs} comparisons (swap={args.swap}, {args.size}px {args.format}), "
        f"server latency {args.latency:g} s, max_concurrency {args.concurrency}"
    )
    print(
        f"  cold: {cold:.2f} s for {requests} requests (ideal {ideal:.2f} s), max in flight {peak}"
    )
    print(f"  overhead per request beyond latency: {(cold - ideal) / requests * 1e3:.1f} ms")
    print(
        f"  from cache: {warm * 1e3:.1f} ms for {args.pairs} comparisons ({judge.cost.cached_calls} cached answers)"
    )


if __name__ == "__main__":
    main()
