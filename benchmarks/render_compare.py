"""Per-candidate render time of two source trees side by side, in alternating rounds.

On a noisy machine a ratio to VTK swings by half between runs; alternating the two trees in
the same minutes shows whether a change moved the renderer's own speed. Each round runs one
process per tree that renders ``benchmarks/render.py``'s random 5-Gaussian TFs through a
sample cache of the foot (256³) at 256², unshaded and shaded, and prints the median.

Run: ``python benchmarks/render_compare.py OLD_SRC NEW_SRC`` (each a checkout's ``src``
folder, e.g. a ``git worktree`` of the older commit), ``--rounds 3``, ``--tfs 50``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
DATA = Path(os.environ.get("INTUITF_DATA", HERE.parent / ".." / "shared" / "data" / "volumes"))

#: One tree's measurement, run in its own process with that tree first on sys.path.
CHILD = r"""
import statistics, sys, time
sys.path.insert(0, sys.argv[1])
from intuitf.render import Camera, VolumeRenderer
from intuitf.volume import load_volume
sys.path.insert(0, sys.argv[3])
from render import random_tfs
vol = load_volume(sys.argv[2])
tfs = random_tfs(int(sys.argv[4]), 0)
out = []
for shading in (False, True):
    cache = VolumeRenderer(vol, size=256, shading=shading, device="cpu").sample_cache(
        Camera(azimuth=30, elevation=20))
    cache.render(tfs[0])  # compile, gradient
    per = []
    for _ in range(3):
        for tf in tfs:
            t = time.perf_counter()
            cache.render(tf)
            per.append(time.perf_counter() - t)
    out.append(f"{statistics.median(per) * 1e3:.2f}")
print(" ".join(out))
"""


def measure(src: str, volume: Path, tfs: int) -> tuple[float, float]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    res = subprocess.run(
        [sys.executable, "-c", CHILD, src, str(volume), str(HERE), str(tfs)],
        capture_output=True, text=True, env=env, check=True,
    )  # fmt: skip
    unshaded, shaded = res.stdout.split()[-2:]
    return float(unshaded), float(shaded)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old", help="the older tree's src folder")
    ap.add_argument("new", help="the newer tree's src folder")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--tfs", type=int, default=50)
    args = ap.parse_args()
    volume = next(DATA.glob("foot_*"), None)
    if volume is None:
        raise SystemExit(f"no foot volume in {DATA} (set INTUITF_DATA)")
    print(f"foot 256³ at 256², {args.tfs} TFs × 3, median ms per candidate (unshaded, shaded)")
    rows: dict[str, list[tuple[float, float]]] = {"old": [], "new": []}
    for r in range(args.rounds):
        for name in ("old", "new"):
            u, s = measure(getattr(args, name), volume, args.tfs)
            rows[name].append((u, s))
            print(f"round {r + 1} {name}: unshaded {u:6.2f}  shaded {s:6.2f}", flush=True)
    for name, got in rows.items():
        us = sorted(u for u, _ in got)
        ss = sorted(s for _, s in got)
        print(f"{name}: median of rounds unshaded {us[len(us) // 2]:.2f} ms, "
              f"shaded {ss[len(ss) // 2]:.2f} ms")  # fmt: skip


if __name__ == "__main__":
    main()
