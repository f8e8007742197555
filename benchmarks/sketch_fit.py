"""How far, and how fast, a sketch's fit goes: the paper's tooth sketch, fitted alone.

The tooth and its strokes are those of ``intent_cases.py --cases tooth-sketch`` (red across the
crown top, yellow across the crown middle, blue across the root, drawn over the default TF's
picture). For each seed it prints the strokes' errors (ΔE per stroke over the structure it lies
on, as the offline judge measures them in a run) for the strokes' hints as they are and for the fitted TF, each structure's ΔE2000
on the labels (``intent_cases.measure``), and the fit's time (the view's sample cache built
once, as a run builds it, then 800 renderings).

    INTUITF_DATA=../shared/data/volumes python benchmarks/sketch_fit.py --seeds 4
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import types
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import intent_cases as ic  # noqa: E402
from intuitf.evaluator.metric import MetricJudge  # noqa: E402
from intuitf.evaluator.types import Intent  # noqa: E402
from intuitf.intent.hints import read_intent  # noqa: E402
from intuitf.intent.regions import sketch_regions  # noqa: E402
from intuitf.intent.sketch_fit import fit_sketch  # noqa: E402
from intuitf.render import VolumeRenderer  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--size", type=int, default=128, help="the fit's picture (a run's: 128)")
    args = ap.parse_args(argv)
    scene = ic._scene("tooth", types.SimpleNamespace(max_dim=None, size=args.size))
    asked = dict(next(c for c in ic.CASES if c.name == "tooth-sketch").asked)
    base, sketch = ic._sketch(scene, asked)
    intent = Intent(kind="sketch", sketch=sketch, base=base)
    t0 = time.perf_counter()
    strokes = read_intent(intent, scene.vol, camera=scene.camera).strokes
    t_hints = time.perf_counter() - t0
    print(f"strokes read in {t_hints:.2f} s: " + ", ".join(
        f"{h.center:.3f} (spread {h.spread:.3f}, height {h.height[0]}-{h.height[1]})"
        for h in strokes))  # fmt: skip
    t0 = time.perf_counter()
    judged = dataclasses.replace(
        intent, part_regions=sketch_regions(intent, scene.vol, scene.camera)
    )
    print(f"strokes grown over their structures in {time.perf_counter() - t0:.2f} s")
    judge = MetricJudge(cache_size=4)
    print(
        f"{'seed':>4} {'fit s':>6}  {'stroke ΔE hints -> fit':<34} ΔE2000 crown top / middle / root"
    )
    for seed in range(args.seeds):
        t0 = time.perf_counter()
        renderer = VolumeRenderer(scene.vol, size=args.size, shading=True, background=(0, 0, 0))
        view = renderer.sample_cache(scene.camera)
        fit = fit_sketch(
            strokes, lambda tf, view=view: judge.stroke_errors(view.render(tf), judged), seed=seed
        )
        seconds = time.perf_counter() - t0
        assert fit is not None
        m = ic.measure(scene, fit.tf, asked)["structures"]
        before = " ".join(f"{v:5.1f}" for v in fit.before)
        after = " ".join(f"{v:5.1f}" for v in fit.after)
        labels = " / ".join(f"{m[n]['dE']:.1f}" for n in ("crown top", "crown middle", "root"))
        print(f"{seed:>4} {seconds:6.1f}  {before} -> {after}   {labels}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
