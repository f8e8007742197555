"""How fast and how well does each Explorer method search? A cheap synthetic judge.

The judge ranks every candidate by the distance of its 64-entry LUT (opacity, and colour
weighted by opacity) to a hidden target TF's LUT, so thousands of generations cost seconds
and the search itself is what is measured. Reports, per method, the best candidate's
distance at a few generations (mean ± sd over seeds) and the time ask + tell take.

    python benchmarks/explorer_synthetic.py
    python benchmarks/explorer_synthetic.py --population 50 --generations 30 --seeds 10
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from intuitf.explorer import METHODS, make_explorer
from intuitf.tf import Gaussian, GaussianTF

TARGETS = {
    "three": GaussianTF(
        (
            Gaussian(0.22, 0.03, 0.04, (0.9, 0.6, 0.5)),
            Gaussian(0.45, 0.02, 0.25, (0.8, 0.2, 0.2)),
            Gaussian(0.78, 0.04, 0.6, (0.95, 0.95, 0.85)),
        )
    ),
    "five": GaussianTF(
        (
            Gaussian(0.12, 0.05, 0.01, (0.7, 0.8, 0.9)),
            Gaussian(0.33, 0.015, 0.08, (0.9, 0.5, 0.3)),
            Gaussian(0.5, 0.02, 0.3, (0.2, 0.7, 0.3)),
            Gaussian(0.66, 0.01, 0.5, (0.3, 0.3, 0.9)),
            Gaussian(0.9, 0.03, 0.9, (1.0, 1.0, 1.0)),
        )
    ),
}


def lut_distance(tf: GaussianTF, target: np.ndarray) -> float:
    lut = tf.lut(64).astype(np.float64)
    a, at = lut[:, 3], target[:, 3]
    col = np.abs(lut[:, :3] * a[:, None] - target[:, :3] * at[:, None]).mean()
    return float(np.abs(a - at).mean() + col)


def run(method: str, target: np.ndarray, seed: int, args) -> tuple[list[float], float]:
    ex = make_explorer(
        method,
        population=args.population,
        n_gaussians=args.gaussians,
        generations=args.generations,
        seed=seed,
    )
    best, spent = [], 0.0
    for _ in range(args.generations):
        t0 = time.perf_counter()
        cands = ex.ask()
        spent += time.perf_counter() - t0
        d = {c.id: lut_distance(c.tf, target) for c in cands}
        ranking = sorted(d, key=d.get)
        best.append(d[ranking[0]])
        t0 = time.perf_counter()
        ex.tell(ranking)
        spent += time.perf_counter() - t0
    return best, spent / args.generations


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--population", type=int, default=24)
    ap.add_argument("--generations", type=int, default=15)
    ap.add_argument("--gaussians", type=int, default=5)
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--methods", nargs="*", default=list(METHODS))
    args = ap.parse_args()
    marks = sorted({0, args.generations // 3, 2 * args.generations // 3, args.generations - 1})
    print(
        f"population {args.population}, {args.generations} generations, "
        f"{args.gaussians} Gaussians, {args.seeds} seeds; best LUT distance (lower is better)"
    )
    for name, tf in TARGETS.items():
        target = tf.lut(64).astype(np.float64)
        print(f"\ntarget {name!r}")
        print(f"{'method':10s}" + "".join(f"{'gen ' + str(g):>16s}" for g in marks) + "  ask+tell")
        for method in args.methods:
            curves, times = zip(
                *(run(method, target, s, args) for s in range(args.seeds)), strict=True
            )
            c = np.array(curves)
            cells = "".join(f"{c[:, g].mean():9.4f} ±{c[:, g].std():.3f}" for g in marks)
            print(f"{method:10s}{cells}  {1e3 * np.mean(times):6.1f} ms")


if __name__ == "__main__":
    main()
