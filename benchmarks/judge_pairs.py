"""The labelled pair set for the offline judge: real renderings, one side clean, one side spoilt.

For each of several real volumes a clean transfer function is made by hand (the structures
people look for, in distinct colours), and it is spoilt five ways, each a thing people reject:

- ``haze``: a faint grey Gaussian over the background's values, a veil filling the volume's box;
- ``noise``: a narrow, fairly opaque Gaussian on the noise just above the background: speckle;
- ``blank``: every Gaussian nearly transparent, so next to nothing shows;
- ``shell``: the outermost material opaque, one shell hiding everything behind it;
- ``washed``: washed-out colours (mixed far toward pale grey) and halved opacity.

Each spoilt rendering is paired with the clean one (order alternating), and the clean one is
the label. ``build`` writes the PNGs and ``labels.json`` to ``tests/data/judge_pairs/`` (the
test ``tests/evaluator/test_metric_pairs.py`` reads them); ``agreement`` prints how often a judge
agrees with the labels, per kind of spoiling, optionally for an older copy of the judge's module
(to measure before and after)::

    python benchmarks/judge_pairs.py build
    python benchmarks/judge_pairs.py agreement
    python benchmarks/judge_pairs.py agreement --module /tmp/old_metric.py
"""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

DATA = Path(
    os.environ.get(
        "INTUITF_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "volumes"
    )
)
OUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "judge_pairs"
SIZE = 128
KINDS = ("haze", "noise", "blank", "shell", "washed")

IVORY = (0.96, 0.93, 0.84)
RED = (0.85, 0.2, 0.15)
BLUE = (0.25, 0.45, 0.95)
ORANGE = (0.95, 0.55, 0.15)
GREEN = (0.3, 0.8, 0.35)
BROWN = (0.6, 0.38, 0.2)

#: Volume file, loading options, camera, clean TF (mean, width, height, colour), and the
#: value range of the outermost material and of the background's noise (normalised).
VOLUMES = {
    "foot": dict(
        file="foot_zfp8lossy_256x256x256_uint8.raw.gz",
        camera=dict(azimuth=20, elevation=20, zoom=1.3),
        clean=[(0.127, 0.02, 0.01, RED), (0.36, 0.03, 0.5, IVORY)],
        shell=0.15,
    ),
    "head": dict(
        file="ctheadstanford_256x256x113_uint16.raw.gz",
        spacing=(1.0, 1.0, 2.0),
        camera=dict(azimuth=0, elevation=0, roll=180, zoom=1.2),
        clean=[(0.33, 0.012, 0.008, RED), (0.64, 0.025, 0.5, IVORY)],
        shell=0.31,
    ),
    "tooth": dict(
        file="tooth_103x94x161_uint8.raw.gz",
        camera=dict(),
        clean=[(0.64, 0.025, 0.08, IVORY), (0.91, 0.03, 0.6, BLUE)],
        shell=0.50,
    ),
    "engine": dict(
        file="engine_256x256x128_uint8.raw.gz",
        camera=dict(azimuth=35, elevation=30, zoom=1.4),
        clean=[(0.50, 0.03, 0.03, BLUE), (0.78, 0.025, 0.5, ORANGE)],
        shell=0.45,
    ),
    "bonsai": dict(
        file="bonsai_256x256x256_uint8.raw.gz",
        camera=dict(elevation=90, zoom=1.3),
        clean=[(0.28, 0.02, 0.15, GREEN), (0.53, 0.03, 0.4, BROWN), (0.8, 0.02, 0.5, ORANGE)],
        shell=0.22,
    ),
    "carp": dict(
        file="carp_zfp8lossy_128x128x256_uint16.raw.gz",
        camera=dict(azimuth=90, elevation=0, roll=90, zoom=1.3),
        clean=[(0.37, 0.015, 0.01, BLUE), (0.6, 0.05, 0.5, IVORY)],
        shell=0.33,
    ),
}


#: Volumes the set does not hold, to check that the judge's constants are not fitted to it:
#: the clean TF is :func:`intuitf.tf.defaults.default_tf` (faint low materials, opaque high
#: ones) and the shell sits on the material most voxels hold.
HOLDOUT = {
    "phantom": dict(file="phantom", camera=dict(azimuth=30, elevation=10)),
    "vismale": dict(
        file="vismale_zfp8lossy_128x256x256_uint8.raw.gz",
        spacing=(1.57774, 0.995861, 1.00797),
        camera=dict(roll=180),
    ),
    "chest": dict(
        file="chestlidc2_256x256x133_uint8.raw.gz",
        spacing=(1.40625, 1.40625, 2.5),
        camera=dict(elevation=20),
    ),
    "headsq": dict(file="headsq_64x64x93_int16.raw.gz", spacing=(3.2, 3.2, 1.5)),
    "neghip": dict(file="neghip_64x64x64_uint8.raw.gz", camera=dict(azimuth=30, elevation=20)),
    "aneurism": dict(file="aneurism_256x256x256_uint8.raw.gz", camera=dict(elevation=20)),
}


def _holdout_config(name: str, counts: np.ndarray) -> dict:
    from intuitf.tf.defaults import default_tf, find_materials

    cfg = dict(HOLDOUT[name])
    tf = default_tf(counts)
    cfg["clean"] = [(g.mean, g.width, g.height, g.color) for g in tf.gaussians]
    mats = find_materials(counts)
    cfg["shell"] = max(mats, key=lambda m: m.fraction).center if mats else 0.5
    return cfg


def _tf(spec):
    from intuitf.tf import Gaussian, GaussianTF

    return GaussianTF(tuple(Gaussian(m, w, h, c) for m, w, h, c in spec))


def spoilt(name: str, kind: str, counts: np.ndarray, cfg: dict | None = None):
    """The clean TF of volume ``name`` spoilt by ``kind`` (see the module docstring)."""
    from intuitf.tf import Gaussian
    from intuitf.tf.defaults import background_cutoff

    cfg = cfg or VOLUMES[name]
    clean = _tf(cfg["clean"])
    cut = background_cutoff(counts)
    n = counts.size
    mode = (int(np.argmax(counts[: max(1, int(cut * n))])) + 0.5) / n
    if kind == "haze":
        g = Gaussian(min(1.0, mode + 0.01), max(0.02, 0.6 * (cut - mode)), 0.004, (0.7, 0.7, 0.7))
        return clean.with_gaussians([*clean.gaussians, g])
    if kind == "noise":
        g = Gaussian(min(1.0, mode + 0.7 * (cut - mode)), 0.006, 0.4, (0.9, 0.9, 0.5))
        return clean.with_gaussians([*clean.gaussians, g])
    if kind == "blank":
        return clean.with_gaussians([replace(g, height=g.height * 0.01) for g in clean.gaussians])
    if kind == "shell":
        g = Gaussian(cfg["shell"], 0.03, 1.0, (0.85, 0.6, 0.5))
        return clean.with_gaussians([*clean.gaussians, g])
    if kind == "washed":
        grey = np.array([0.85, 0.85, 0.85])
        return clean.with_gaussians(
            [
                replace(
                    g,
                    color=tuple(float(v) for v in 0.2 * np.array(g.color) + 0.8 * grey),
                    height=g.height * 0.5,
                )
                for g in clean.gaussians
            ]
        )
    raise ValueError(kind)


def build(out: Path = OUT, size: int = SIZE, holdout: bool = False) -> None:
    """Render every volume's clean and spoilt TFs and write the PNGs and labels.json.

    ``holdout``: the volumes of :data:`HOLDOUT` instead (a check, not the test set).
    """
    from PIL import Image

    from intuitf.render import Camera, VolumeRenderer
    from intuitf.volume import load_volume, phantom

    out.mkdir(parents=True, exist_ok=True)
    pairs = []
    k = 0
    for name in HOLDOUT if holdout else VOLUMES:
        cfg = HOLDOUT[name] if holdout else VOLUMES[name]
        if cfg["file"] == "phantom":
            vol = phantom()
        else:
            vol = load_volume(DATA / cfg["file"], spacing=cfg.get("spacing"))
        counts, _ = vol.histogram()
        if holdout:
            cfg = _holdout_config(name, counts)
        cache = VolumeRenderer(vol, size=size).sample_cache(Camera(**cfg.get("camera", {})))
        clean_file = f"{name}_clean.png"
        Image.fromarray(cache.render(_tf(cfg["clean"]))).save(out / clean_file, optimize=True)
        for kind in KINDS:
            f = f"{name}_{kind}.png"
            img = cache.render(spoilt(name, kind, counts, cfg))
            Image.fromarray(img).save(out / f, optimize=True)
            first, second = (clean_file, f) if k % 2 == 0 else (f, clean_file)
            pairs.append(
                dict(
                    volume=name,
                    kind=kind,
                    first=first,
                    second=second,
                    better="first" if first == clean_file else "second",
                )
            )
            k += 1
        print(f"{name}: done", flush=True)
    labels = {
        "about": "Real renderings; in each pair one side is clean and the other spoilt "
        "(haze, noise, blank, occluding shell, washed-out colours). 'better' names the clean "
        "side. Built by benchmarks/judge_pairs.py.",
        "size": size,
        "pairs": pairs,
    }
    (out / "labels.json").write_text(json.dumps(labels, indent=1) + "\n")
    print(f"{len(pairs)} pairs in {out}")


def load_pairs(folder: Path = OUT):
    """(pair record, first image, second image) for every labelled pair."""
    from intuitf.imageio import load_image

    labels = json.loads((folder / "labels.json").read_text())
    return [
        (p, load_image(folder / p["first"]), load_image(folder / p["second"]))
        for p in labels["pairs"]
    ]


def agreement(judge, folder: Path = OUT, aspect_set: str = "quality") -> dict[str, float]:
    """Share of pairs where ``judge``'s overall verdict names the labelled side, per kind."""
    from intuitf.evaluator.types import Intent
    from intuitf.intent.aspects import aspects_for

    aspects = aspects_for(aspect_set)
    hits: dict[str, list[float]] = {}
    for p, a, b in load_pairs(folder):
        v = asyncio.run(judge.compare(a, b, aspects, Intent()))
        score = {"first": 1.0, "second": 0.0, "tie": 0.5}[v.overall.value]
        hit = score if p["better"] == "first" else 1.0 - score
        hits.setdefault(p["kind"], []).append(hit)
    out = {k: float(np.mean(v)) for k, v in hits.items()}
    out["all"] = float(np.mean([h for v in hits.values() for h in v]))
    return out


def _judge_from(module_path: str | None):
    if module_path is None:
        from intuitf.evaluator.metric import MetricJudge

        return MetricJudge()
    spec = importlib.util.spec_from_file_location("metric_under_test", module_path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["metric_under_test"] = mod
    spec.loader.exec_module(mod)
    return mod.MetricJudge()


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("command", choices=("build", "agreement"))
    ap.add_argument("--module", help="agreement: a file holding another MetricJudge to measure")
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument(
        "--holdout", action="store_true", help="build: the volumes the set does not hold instead"
    )
    args = ap.parse_args()
    if args.command == "build":
        build(Path(args.out), holdout=args.holdout)
        return 0
    res = agreement(_judge_from(args.module), Path(args.out))
    print(
        "agreement with the labels (tie = half): "
        + "  ".join(f"{k} {v:.2f}" for k, v in res.items())
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
