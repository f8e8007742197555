"""What each part of the default Explorer adds: the recovery task with one part switched off.

The task of ``benchmarks/recovery.py`` (hide a target TF, the judge prefers the rendering with
the higher SSIM to its picture, 10 % noise, 20 % position bias, population 32, 12
generations), run for many seeds with the in-process :class:`~intuitf.testing.OracleJudge`,
which answers by the fake server's rule without HTTP (several times faster, so 16 seeds take
about a minute per configuration on 2 cores). Configurations:

- ``default``: the product as shipped;
- ``no-palette``: no colours from the intent (``RunSettings.palette_hint=False``);
- ``no-local``: no mutated copies of the best (``local_share`` 0 in every stage);
- ``pair-by-order``: crossover pairs k-th lowest with k-th lowest, as the paper does;
- ``no-history``: each tournament fits only its own verdicts;
- ``full-history``: earlier generations' verdicts at full weight (the default fades them by
  ``HISTORY_FADE`` per generation of age, the judge being noisy);
- ``noise-free``: the default with a judge that never errs (what the search itself reaches);
- ``random``: random search with the same judge, for reference.

    python benchmarks/recovery_ablation.py                 # engine, 16 seeds, every configuration
    python benchmarks/recovery_ablation.py --volume tooth --seeds 8 --configs default,no-palette
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from multiprocessing import Pool

import numpy as np

from intuitf.evaluator.types import Intent
from intuitf.render import VolumeRenderer
from intuitf.session import RunSettings, Session
from intuitf.testing import OracleJudge
from intuitf.volume import load_volume

# The task itself (targets, cameras, measures) is recovery.py's, next to this script.
from recovery import CAMERAS, DATA, TARGETS, similarity, ssim_oracle  # isort: skip

CONFIGS = (
    "default",
    "no-palette",
    "no-local",
    "pair-by-order",
    "no-history",
    "full-history",
    "noise-free",
    "random",
)


_switched: set[str] = set()


def _switch_off(config: str) -> None:
    """Change this worker process's defaults for ``config`` (each worker runs one config)."""
    from intuitf.explorer import stages

    if config in _switched:
        return
    _switched.add(config)
    if config == "no-local":
        for name, preset in list(stages.STAGES.items()):
            stages.STAGES[name] = replace(preset, local_share=stages.Decay(0.0, 0.0))
    elif config == "pair-by-order":
        for name, preset in list(stages.STAGES.items()):
            stages.STAGES[name] = replace(preset, pair_by_mean=False)
    elif config == "no-history":
        from intuitf.evaluator import tournament

        class WithoutHistory(tournament.SwissTournament):
            async def run(self, images, ids, prior=None, progress=None, history=(), **kw):
                return await super().run(images, ids, prior=prior, progress=progress, **kw)

        tournament.SwissTournament = WithoutHistory  # the session imports it at each step
    elif config == "full-history":
        from intuitf.session import session

        session.HISTORY_FADE = 1.0  # what the session weighs a model's earlier verdicts by


_volumes: dict[str, tuple] = {}


def _setup(volume: str, size: int):
    if volume not in _volumes:
        key = next(k for k in TARGETS if k.startswith(volume))
        vol = load_volume(DATA / key)
        target = VolumeRenderer(vol, size=size, shading=False).render(TARGETS[key], CAMERAS[key])
        _volumes[volume] = (vol, CAMERAS[key], target)
    return _volumes[volume]


def _run(job: tuple) -> list[float]:
    config, volume, seed, population, generations, size = job
    _switch_off(config)
    vol, camera, target = _setup(volume, size)
    noisy = config != "noise-free"
    judge = OracleJudge(
        ssim_oracle(target),
        noise=0.1 if noisy else 0.0,
        position_bias=0.2 if noisy else 0.0,
        seed=1000 + seed,
    )
    settings = RunSettings(
        population=population,
        generations=generations,
        explorer="random" if config == "random" else "ga",
        image_size=size,
        output_size=size,
        seed=seed,
        shading=False,
        camera=camera.to_dict(),
        palette_hint=config != "no-palette",
    )
    session = Session.create(
        vol, intent=Intent(kind="image", reference=target), judge=judge, settings=settings
    )
    out = []
    while not session.done:
        rec = session.step()
        out.append(similarity(session.image(rec.best_id, session.tfs[rec.best_id]), target)[0])
    session.close()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--volume", default="engine", choices=("engine", "tooth"))
    ap.add_argument("--seeds", type=int, default=16)
    ap.add_argument("--configs", default=",".join(CONFIGS))
    ap.add_argument("--population", type=int, default=32)
    ap.add_argument("--generations", type=int, default=12)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    configs = args.configs.split(",")
    unknown = sorted(set(configs) - set(CONFIGS))
    if unknown:
        ap.error(f"unknown configurations {unknown}; choose from {list(CONFIGS)}")
    marks = sorted(g for g in {0, 2, 5, 8, args.generations - 1} if g < args.generations)
    print(
        f"{args.volume}: SSIM of each generation's best to the target, mean of {args.seeds} "
        f"seeds (± standard error at the last generation)"
    )
    print(f"{'config':14s} " + " ".join(f"g{g:02d}  " for g in marks) + " final")
    for config in configs:
        jobs = [
            (config, args.volume, s, args.population, args.generations, args.size)
            for s in range(args.seeds)
        ]
        # A fresh pool per configuration: _switch_off changes a worker's defaults for good.
        with Pool(args.workers) as pool:
            runs = np.array(pool.map(_run, jobs))
        mean = runs.mean(axis=0)
        se = runs[:, -1].std(ddof=1) / np.sqrt(len(runs)) if len(runs) > 1 else 0.0
        cells = " ".join(f"{mean[g]:.3f}" for g in marks)
        print(f"{config:14s} {cells}  {mean[-1]:.3f} ± {se:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
