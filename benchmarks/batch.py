"""``intuitf batch`` at scale: throughput on the pool and on Ray, and the case study's recovery.

**Throughput.** 16 volumes (8 real ones read as they are, 8 larger CTs resampled to at most 64
voxels per axis) against the fake model server answering after 1 s (fixed), with the real
``MLLMJudge`` over loopback HTTP: wall time, volumes per hour, model calls, and how the volumes'
time splits between rendering (busy time on the render thread) and waiting for the judge, for
1, 2 and 4 workers on the process pool and on a local Ray instance. Then an extrapolation to
1,000 volumes on a 16-node cluster, and what would limit it.

**Recovery (the paper's case study).** A TF of the foot CT and its rendering are the reference;
on the chest, the heads and the other CTs, the batch starts once from the foot TF carried over
by materials and once from each volume's default TF, same search (offline metric judge). It
reports the similarity of each start and each result to the reference look (colour
distribution of the rendered materials).

    python benchmarks/batch.py                       # both parts (a few minutes)
    python benchmarks/batch.py --part throughput --workers 1,2 --backends pool
    python benchmarks/batch.py --part recovery
    python benchmarks/batch.py --quick               # 8 volumes, 1 and 2 workers

Figures depend on the machine and on what else runs on it; the script prints the load average.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from intuitf.batch import BatchRequest, run_batch
from intuitf.imageio import save_png
from intuitf.render import Camera, VolumeRenderer
from intuitf.testing.fake_mllm import FakeMLLMServer
from intuitf.tf import save_tf
from intuitf.tf.defaults import default_tf
from intuitf.volume import load_volume

DATA = Path(
    os.environ.get(
        "INTUITF_DATA", Path(__file__).resolve().parents[2] / "shared" / "data" / "volumes"
    )
)

#: Read as they are (the batch's --max-dim 64 leaves most of them alone).
REAL = [
    "nucleon_41x41x41_uint8.raw.gz",
    "neghip_64x64x64_uint8.raw.gz",
    "fuel_64x64x64_uint8.raw.gz",
    "ironprotein_68x68x68_uint8.raw.gz",
    "hydrogenorbital3d_64x64x64_float32.raw.gz",
    "headsq_64x64x93_int16.raw.gz",
    "hydrogenatom_128x128x128_uint8.raw.gz",
    "turbulentcombustion_128x256x32_uint8.raw.gz",
]
#: Resampled to at most 64 voxels per axis and saved as .npy.
RESAMPLED = [
    "foot_zfp8lossy_256x256x256_uint8.raw.gz",
    "chestlidc2_256x256x133_uint8.raw.gz",
    "ctheadstanford_256x256x113_uint16.raw.gz",
    "vismale_zfp8lossy_128x256x256_uint8.raw.gz",
    "engine_256x256x128_uint8.raw.gz",
    "bonsai_256x256x256_uint8.raw.gz",
    "tooth_103x94x161_uint8.raw.gz",
    "carp_zfp8lossy_128x128x256_uint16.raw.gz",
]
FOOT = "foot_zfp8lossy_256x256x256_uint8.raw.gz"
#: The case study's targets: the chest, the heads, and the other CT scans.
CT_TARGETS = [
    "chestlidc2_256x256x133_uint8.raw.gz",
    "ctheadstanford_256x256x113_uint16.raw.gz",
    "headsq_64x64x93_int16.raw.gz",
    "vismale_zfp8lossy_128x256x256_uint8.raw.gz",
    "carp_zfp8lossy_128x128x256_uint16.raw.gz",
    "tooth_103x94x161_uint8.raw.gz",
]
CAMERA = Camera(azimuth=30.0, elevation=20.0)


def _stem(name: str) -> str:
    return name.split("_")[0]


#: The foot's "visualization standard": faint blue soft tissue, semi-transparent red muscle,
#: opaque golden bone (colours no default TF uses, so a start from one is not already there).
STANDARD_COLOURS = [(0.35, 0.55, 0.95), (0.9, 0.3, 0.25), (1.0, 0.8, 0.35), (1.0, 0.95, 0.7)]


def make_reference(folder: Path, max_dim: int, size: int) -> dict:
    """The foot's TF (on its histogram materials, in the standard's colours) and rendering."""
    from dataclasses import replace

    foot = load_volume(DATA / FOOT, max_dim=max_dim)
    base = default_tf(foot.histogram()[0], foot.value_range)
    gs = [replace(g, color=STANDARD_COLOURS[min(i, len(STANDARD_COLOURS) - 1)])
          for i, g in enumerate(base.gaussians)]  # fmt: skip
    tf = replace(base, gaussians=tuple(gs), name="foot standard")
    folder.mkdir(parents=True, exist_ok=True)
    np.save(folder / "foot.npy", np.asarray(foot.data, np.float32))
    save_tf(tf, folder / "foot.tf.json")
    picture = VolumeRenderer(foot, size=size).render(tf, CAMERA)
    save_png(picture, folder / "foot.png")
    return {"tf": folder / "foot.tf.json", "volume": DATA / FOOT, "picture": folder / "foot.png",
            "max_dim": max_dim}  # fmt: skip


def make_volumes(folder: Path, n: int) -> list[str]:
    folder.mkdir(parents=True, exist_ok=True)
    real, resampled = REAL[: (n + 1) // 2], RESAMPLED[: n // 2]
    for name in real:
        (folder / name).symlink_to(DATA / name)
    for name in resampled:
        vol = load_volume(DATA / name, max_dim=64)
        np.save(folder / f"{_stem(name)}-r64.npy", np.asarray(vol.data, np.float32))
    return [str(folder)]


def _settings(population: int, generations: int, size: int, output: int) -> dict:
    return dict(population=population, generations=generations, image_size=size,
                output_size=output, top_k=1, seed=0, camera=CAMERA.to_dict(),
                stages=[["customize", generations]])  # fmt: skip


def throughput(args, work: Path) -> list[dict]:
    ref = make_reference(work / "reference", 64, args.output_size)
    volumes = make_volumes(work / "vols", args.volumes)
    from intuitf.imageio import load_image

    rows = []
    with FakeMLLMServer(target=load_image(ref["picture"]), latency=args.latency) as srv:
        ray_init_s = None
        for backend in args.backends:
            if backend == "ray":
                import ray

                t = time.perf_counter()
                ray.init(num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False,
                         configure_logging=False)  # fmt: skip
                ray_init_s = time.perf_counter() - t
            for w in args.workers:
                root = work / f"{backend}-{w}"
                before = srv.stats.requests
                req = BatchRequest(
                    root=str(root), reference=str(ref["tf"]), reference_volume=str(ref["volume"]),
                    volumes=volumes, evaluator=srv.base_url, reader={"max_dim": 64},
                    settings=_settings(args.population, args.generations, args.size,
                                       args.output_size),
                    workers=w, per_worker=args.per_worker,
                    ray="local" if backend == "ray" else None,
                )  # fmt: skip
                t0 = time.perf_counter()
                summary = run_batch(req)
                wall = time.perf_counter() - t0
                t = summary["totals"]
                row = {
                    "backend": backend,
                    "workers": w,
                    "per_worker": args.per_worker,
                    "volumes": t["volumes"],
                    "completed": t["completed"],
                    "wall_s": wall,
                    "volumes_per_hour": 3600.0 * t["completed"] / wall,
                    "calls": t["calls"],
                    "server_requests": srv.stats.requests - before,
                    "calls_per_volume": t["calls"] / max(1, t["completed"]),
                    "volume_s": t["volume_seconds"],
                    "render_s": t["render_s"],
                    "judge_s": t["judge_s"],
                    "open_s": t["open_s"],
                    "outputs_s": t["outputs_s"],
                    "max_in_flight": srv.stats.max_in_flight,
                }
                rows.append(row)
                print(_row_text(row), flush=True)
                shutil.rmtree(root, ignore_errors=True)
            if backend == "ray":
                import ray

                ray.shutdown()
    if ray_init_s is not None:
        print(f"(starting the local Ray instance took {ray_init_s:.1f} s, not counted above)")
    return rows


def _row_text(r: dict) -> str:
    n = max(1, r["completed"])
    rest = r["volume_s"] - r["render_s"] - r["judge_s"] - r["open_s"] - r["outputs_s"]
    return (
        f"| {r['backend']} | {r['workers']} | {r['completed']}/{r['volumes']} | {r['wall_s']:.0f} "
        f"| {r['volumes_per_hour']:.0f} | {r['calls']} ({r['calls_per_volume']:.0f}/vol) "
        f"| {r['render_s'] / n:.2f} / {r['judge_s'] / n:.1f} / {r['open_s'] / n:.1f} / "
        f"{r['outputs_s'] / n:.1f} / {rest / n:.1f} |"
    )


def _rounds(population: int) -> int:
    """Rounds of one generation's Swiss tournament."""
    return math.ceil(math.log2(population)) + 2


def extrapolate(rows: list[dict], latency: float, args) -> str:
    """1,000 volumes on a 16-node cluster, from the per-volume figures measured here.

    Per volume: C model calls, R s of rendering and O s of other CPU work (reading, opening,
    writing outputs), J s waiting on the judge. With N nodes of K cores, one worker per core
    and p volumes in flight per worker (S = N K p), the batch takes at least the longest of
    CPU: 1000 (R + O) / (N K),  latency: ceil(1000 / S) (J + R + O),  rate: 1000 C / RPM.
    """
    best = max(rows, key=lambda r: r["volumes_per_hour"])
    n = best["completed"] or 1
    C = best["calls"] / n
    R = best["render_s"] / n
    J = best["judge_s"] / n
    O = max(0.0, (best["volume_s"] - best["render_s"] - best["judge_s"]) / n)  # noqa: E741
    N, K, p = 16, 16, args.per_worker
    rounds = _rounds(args.population) * args.generations
    # Default settings: population 32, 12 generations, 256 px (scaled from the measurement:
    # calls and judge waits per tournament round, render time per candidate pixel).
    d_rounds = _rounds(32) * 12
    d_scale = (32 * 12 * 256**2) / (args.population * args.generations * args.size**2)
    cases = [
        (f"these settings (population {args.population}, {args.generations} generations, "
         f"{args.size} px)", C, R, O, J),
        ("default settings (population 32, 12 generations, 256 px)",
         C * (32 / args.population) * d_rounds / rounds, R * d_scale, O, J * d_rounds / rounds),
    ]  # fmt: skip
    lines = [
        f"Measured per volume (best row: {best['backend']}, {best['workers']} workers): "
        f"{C:.0f} calls, {R:.1f} s rendering, {O:.1f} s other CPU work, {J:.1f} s waiting on "
        f"{latency:g}-s answers.",
        f"1,000 volumes on {N} nodes x {K} cores ({N * K} workers, {p} volumes each in flight):",
    ]
    for label, c, r, o, j in cases:
        t_cpu = 1000 * (r + o) / (N * K) / 60
        t_lat = math.ceil(1000 / (N * K * p)) * (j + r + o) / 60
        rpm_needed = 1000 * c / max(t_cpu, t_lat)
        rate = ", ".join(f"{rpm:,} RPM: {1000 * c / rpm / 60:.1f} h" for rpm in (500, 5000, 30000))
        lines.append(
            f"- {label}: {1000 * c:,.0f} calls; CPU {t_cpu:.1f} min, latency {t_lat:.1f} min: "
            f"about {max(t_cpu, t_lat):.0f} min if the provider took {rpm_needed:,.0f} requests/min. "
            f"Rate-limited: {rate}."
        )
    return "\n".join(lines)


def recovery(args, work: Path) -> list[dict]:
    """Both starts (carried foot TF, each volume's default TF), with two judges: the offline
    metric judge (colour *and* structure similarity to the picture, SSIM included) and the fake
    model server answering by the look alone (the colour-distribution similarity that the table
    reports), over HTTP like a model."""
    from intuitf.batch.reference import similarity
    from intuitf.imageio import load_image

    ref = make_reference(work / "rec-reference", args.rec_max_dim, args.rec_output)
    picture = load_image(ref["picture"])
    vols = work / "rec-vols"
    vols.mkdir(parents=True, exist_ok=True)
    for name in CT_TARGETS:
        (vols / name).symlink_to(DATA / name)
    settings = _settings(args.rec_population, args.rec_generations, args.rec_size,
                         args.rec_output)  # fmt: skip
    results: dict[tuple[str, bool], dict] = {}
    with FakeMLLMServer(score=lambda img: similarity(img, picture)) as srv:
        for judge, evaluator in (("metric", "metric"), ("look", srv.base_url)):
            for carry in (True, False):
                root = work / f"rec-{judge}-{'carried' if carry else 'default'}"
                req = BatchRequest(
                    root=str(root), reference=str(ref["tf"]), reference_volume=str(ref["volume"]),
                    volumes=[str(vols)], evaluator=evaluator, reader={"max_dim": args.rec_max_dim},
                    settings=settings, workers=args.rec_workers, per_worker=2, carry=carry,
                )  # fmt: skip
                t0 = time.perf_counter()
                summary = run_batch(req)
                results[(judge, carry)] = {v["key"]: v for v in summary["volumes"]}
                print(f"recovery, {judge} judge, {'carried' if carry else 'default'} start: "
                      f"{time.perf_counter() - t0:.0f} s, {summary['totals']['calls']} model calls",
                      flush=True)  # fmt: skip
    rows = []
    for key in results[("metric", True)]:
        row = {"volume": key}
        for judge in ("metric", "look"):
            c, d = results[(judge, True)][key], results[(judge, False)][key]
            row[f"{judge}_carried_start"] = c["start_similarity"]
            row[f"{judge}_carried_best"] = c["similarity"]
            row[f"{judge}_default_start"] = d["start_similarity"]
            row[f"{judge}_default_best"] = d["similarity"]
        rows.append(row)
    return rows


def _f(v) -> str:
    return "–" if v is None else f"{v:.3f}"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--part", choices=["both", "throughput", "recovery"], default="both")
    p.add_argument("--quick", action="store_true", help="8 volumes; 1 and 2 workers")
    p.add_argument("--volumes", type=int, default=16)
    p.add_argument("--workers", default="1,2,4")
    p.add_argument("--backends", default="pool,ray")
    p.add_argument("--per-worker", type=int, default=4)
    p.add_argument("--latency", type=float, default=1.0)
    p.add_argument("--population", type=int, default=8)
    p.add_argument("--generations", type=int, default=2)
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--output-size", type=int, default=128)
    p.add_argument("--rec-population", type=int, default=12)
    p.add_argument("--rec-generations", type=int, default=4)
    p.add_argument("--rec-size", type=int, default=96)
    p.add_argument("--rec-output", type=int, default=160)
    p.add_argument("--rec-max-dim", type=int, default=96)
    p.add_argument("--rec-workers", type=int, default=2)
    p.add_argument("--json", type=Path, help="also write the figures here")
    args = p.parse_args(argv)
    args.workers = [int(w) for w in args.workers.split(",")]
    args.backends = [b for b in args.backends.split(",") if b]
    if args.quick:
        args.volumes, args.workers = 8, [1, 2]
    if "ray" in args.backends:
        try:
            import ray  # noqa: F401
        except ImportError:
            print("Ray is not installed: only the pool is measured (pip install 'intuitf[ray]').")
            args.backends = [b for b in args.backends if b != "ray"]
    if not DATA.is_dir():
        sys.exit(f"real volumes not found in {DATA} (set INTUITF_DATA)")
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start")
    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="intuitf-batch-bench-") as tmp:
        work = Path(tmp)
        if args.part in ("both", "throughput"):
            print(
                f"\n## Throughput: {args.volumes} volumes, fake model at {args.latency:g} s, "
                f"population {args.population}, {args.generations} generations, {args.size} px, "
                f"{args.per_worker} volumes in flight per worker\n"
            )
            print("| backend | workers | done | wall s | volumes/h | model calls | s per volume: "
                  "render / judge wait / open / outputs / rest |")  # fmt: skip
            print("|---|---|---|---|---|---|---|")
            rows = throughput(args, work)
            out["throughput"] = rows
            print("\n" + extrapolate(rows, args.latency, args))
        if args.part in ("both", "recovery"):
            print(
                f"\n## Recovery: foot TF as the reference, population "
                f"{args.rec_population}, {args.rec_generations} generations, {args.rec_size} px\n"
            )
            rows = recovery(args, work)
            out["recovery"] = rows
            print("\n| volume | carried start | default start | metric judge: from carried | "
                  "from default | look judge: from carried | from default |")  # fmt: skip
            print("|---|---|---|---|---|---|---|")
            keys = ["metric_carried_start", "metric_default_start", "metric_carried_best",
                    "metric_default_best", "look_carried_best", "look_default_best"]  # fmt: skip
            for r in rows:
                print(f"| {r['volume']} | " + " | ".join(_f(r[k]) for k in keys) + " |")
            mean = {k: float(np.mean([r[k] for r in rows if r[k] is not None])) for k in keys}
            print("| mean | " + " | ".join(f"{mean[k]:.3f}" for k in keys) + " |")
    print(f"\nload average at the end: {os.getloadavg()[0]:.1f}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=2, default=str))


if __name__ == "__main__":
    main()
