"""Renderer speed: sample-cache build, ms per candidate TF, new-camera render, memory, and
VTK's fixed-point ray caster re-rendering the same TFs (the CPU baseline).

Run: ``python benchmarks/render.py`` (``--quick`` for fewer TFs, ``--no-vtk`` to skip VTK).
Figures are medians; the machine may be shared, so run it twice before believing a figure.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "render"))  # vtkref: the VTK scene the tests use

from intuitf.render import Camera, VolumeRenderer  # noqa: E402
from intuitf.tf import Gaussian, GaussianTF  # noqa: E402
from intuitf.volume import load_volume, phantom  # noqa: E402

DATA = Path(os.environ.get("INTUITF_DATA", ROOT / ".." / "shared" / "data" / "volumes"))


def random_tfs(n: int, seed: int = 0) -> list[GaussianTF]:
    rng = np.random.default_rng(seed)
    return [
        GaussianTF(
            tuple(
                Gaussian(
                    mean=float(rng.uniform(0.05, 1.0)),
                    width=float(rng.uniform(0.01, 0.12)),
                    height=float(rng.uniform(0.005, 0.6)),
                    color=tuple(float(c) for c in rng.uniform(0, 1, 3)),
                )
                for _ in range(5)
            )
        )
        for _ in range(n)
    ]


def timed(fn, repeat: int = 1) -> tuple[float, object]:
    best, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best.append(time.perf_counter() - t)
    return statistics.median(best), out


def bench_volume(name, vol, tfs, sizes, use_vtk: bool, sample_distance: float = 0.5) -> None:
    cam = Camera(azimuth=30, elevation=20)
    print(f"\n== {name}: dims {vol.dims}, {len(tfs)} random 5-Gaussian TFs, camera az 30 el 20")
    for shading in (False, True):
        for size in sizes:
            r = VolumeRenderer(vol, size=size, shading=shading, sample_distance=sample_distance)
            if shading:
                tg, _ = timed(r.gradient)  # once per volume
            r.render(tfs[0], cam)  # warm (JIT from the on-disk cache)
            r.sample_cache(cam).render(tfs[0])
            tracemalloc.start()
            tb, cache = timed(lambda r=r: r.sample_cache(cam), repeat=3)
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            per = [timed(lambda t=t, c=cache: c.render(t))[0] for t in tfs]
            tfull = statistics.median(
                timed(lambda t=t, r=r: r.render(t, Camera(azimuth=75, elevation=-10)))[0]
                for t in tfs[:10]
            )
            line = (
                f"{'shaded  ' if shading else 'unshaded'} {size}²: cache build {tb * 1e3:6.0f} ms"
                f" ({cache.nbytes / 1e6:5.1f} MB, {cache.n_samples / 1e6:4.1f} M samples,"
                f" build peak {peak / 1e6:5.0f} MB) | per candidate {statistics.median(per) * 1e3:5.1f}"
                f" ms (p90 {np.percentile(per, 90) * 1e3:5.1f}) | new camera full render"
                f" {tfull * 1e3:5.0f} ms"
            )
            if shading:
                line += f" | gradient (once) {tg * 1e3:.0f} ms"
            if use_vtk:
                from vtkref import VTKScene

                scene = VTKScene(r, "fixed")
                scene.render(tfs[0], cam)
                tv = [
                    timed(lambda t=t, s=scene: s.render(t, cam))[0]
                    for t in tfs[: min(20, len(tfs))]
                ]
                scene.close()
                ratio = statistics.median(tv) / statistics.median(per)
                line += f" | VTK fixed-point {statistics.median(tv) * 1e3:5.0f} ms ({ratio:4.1f}×)"
            print(line, flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10 TFs instead of 50")
    ap.add_argument("--no-vtk", action="store_true", help="skip the VTK baseline")
    ap.add_argument(
        "--sample-distance",
        type=float,
        default=0.5,
        help="step along rays in voxels, for intuitf and VTK alike (default 0.5; VTK's own is 1)",
    )
    args = ap.parse_args()
    tfs = random_tfs(10 if args.quick else 50)
    use_vtk = not args.no_vtk
    if use_vtk:
        from vtkref import vtk_available

        reason = vtk_available()
        if reason:
            print(f"VTK baseline skipped: {reason}")
            use_vtk = False
    import numba

    print(f"numba {numba.__version__}, {numba.get_num_threads()} threads, {os.cpu_count()} CPUs")
    t = time.perf_counter()
    foot = load_volume(DATA / "foot_zfp8lossy_256x256x256_uint8.raw.gz")
    print(f"foot loaded in {time.perf_counter() - t:.2f} s")
    bench_volume("foot 256³", foot, tfs, (256, 512), use_vtk, args.sample_distance)
    bench_volume("phantom 160³", phantom(size=160), tfs, (256,), use_vtk, args.sample_distance)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"\npeak resident memory of this process: {rss:.0f} MB")


if __name__ == "__main__":
    main()
