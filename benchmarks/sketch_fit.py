"""How far, and how fast, a sketch's fit goes: the paper's tooth sketch, fitted alone.

The tooth and its strokes are those of ``intent_cases.py --cases tooth-sketch`` (red across the
crown top, yellow across the crown middle, blue across the root, drawn over the default TF's
picture). For each seed it fits the strokes as a run does (``intuitf.session.helpers``:
the strokes grown over their structures, the views' sample caches built, then 800 renderings
lit and 800 unshaded) and prints the strokes' errors (per stroke, the mean of the offline
judge's ΔE over the structure it lies on in the lit picture and of the structure's colour in
the unshaded one) for the strokes' hints as they are and for the fitted TF, each structure's
ΔE2000 on the labels (``intent_cases.measure``), and the fit's time, all of it.

    INTUITF_DATA=../shared/data/volumes python benchmarks/sketch_fit.py --seeds 4
"""

from __future__ import annotations

import argparse
import sys
import time
import types
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import intent_cases as ic  # noqa: E402
from intuitf.evaluator.types import Intent  # noqa: E402
from intuitf.intent.hints import read_intent  # noqa: E402
from intuitf.session.helpers import _fit_sketch as fit_for_run  # noqa: E402
from intuitf.session.settings import RunSettings  # noqa: E402


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
    reading = read_intent(intent, scene.vol, camera=scene.camera)
    strokes = reading.strokes
    t_hints = time.perf_counter() - t0
    print(f"strokes read in {t_hints:.2f} s: " + ", ".join(
        f"{h.center:.3f} (spread {h.spread:.3f}, height {h.height[0]}-{h.height[1]})"
        for h in strokes))  # fmt: skip
    print(
        f"{'seed':>4} {'fit s':>6}  {'stroke error hints -> fit':<34}"
        " ΔE2000 crown top / middle / root"
    )
    for seed in range(args.seeds):
        settings = RunSettings(image_size=args.size, output_size=args.size, seed=seed,
                               shading=True, camera=scene.camera.to_dict())  # fmt: skip
        t0 = time.perf_counter()
        fit = fit_for_run(intent, settings, scene.vol, reading)
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
