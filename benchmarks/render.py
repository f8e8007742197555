"""Renderer speed: sample-cache build, ms per candidate TF, new-camera render, memory, and
VTK's fixed-point ray caster re-rendering the same TFs (the CPU baseline).

Run: ``python benchmarks/render.py`` (``--quick`` for fewer TFs, ``--no-vtk`` to skip VTK).
Figures are medians; the machine may be shared, so run it twice before believing a figure.

``--preintegration``: what classifying each segment between samples (the default,
:mod:`intuitf.tf.preintegration`) buys against classifying each sample alone (VTK's way,
``preintegrated=False``): each picture's mean CIEDE2000 to the same TF sampled ten times finer
(post-classified, step 0.05), and the time per candidate and per new-camera picture, for TFs
with thin Gaussians (a TF fitted to the tooth's sketch, random ones 0.002-0.01 wide) and the
random TFs above, on the tooth and the foot at 256².

On a machine with an NVIDIA GPU (``pip install -e '.[cuda,test]'``):
``python benchmarks/render.py --device cuda`` times the CUDA backend: a population of 50 random
TFs rendered in one launch at 256², 512² and 1024², unshaded and shaded, for the foot (256³) and
the foot upsampled to 512³; the sample-cache build and a direct render from a new camera; the
CPU path and VTK's GPU ray caster (where VTK gets an EGL context; the GL renderer it got is
printed, llvmpipe meaning software) on the same machine in the same run; the GPU pictures'
agreement with the CPU's; and how close each candidate comes to the GPU's memory-bandwidth
limit for the bytes of the sample cache it reads. ``--ptx`` compiles the CUDA kernels for an
architecture and reports their registers without needing a GPU (needs the ``cuda`` extra).
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
sys.path.insert(0, str(ROOT / "tests"))  # helpers.vtkref: the VTK scene the tests use

from intuitf.render import Camera, VolumeRenderer  # noqa: E402
from intuitf.tf import Gaussian, GaussianTF  # noqa: E402
from intuitf.volume import load_volume, phantom  # noqa: E402

DATA = Path(os.environ.get("INTUITF_DATA", ROOT / ".." / "shared" / "data" / "volumes"))


def random_tfs(
    n: int,
    seed: int = 0,
    *,
    gaussians: int = 5,
    means: tuple[float, float] = (0.05, 1.0),
    widths: tuple[float, float] = (0.01, 0.12),
    heights: tuple[float, float] = (0.005, 0.6),
) -> list[GaussianTF]:
    rng = np.random.default_rng(seed)
    return [
        GaussianTF(
            tuple(
                Gaussian(
                    mean=float(rng.uniform(*means)),
                    width=float(rng.uniform(*widths)),
                    height=float(rng.uniform(*heights)),
                    color=tuple(float(c) for c in rng.uniform(0, 1, 3)),
                )
                for _ in range(gaussians)
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
                from helpers.vtkref import VTKScene

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


def _thin_tfs(n: int, seed: int = 1) -> list[GaussianTF]:
    """Random TFs whose Gaussians are thinner than a surface's values change between samples
    (0.002-0.01 of the range), as sketch fits and narrow picks make."""
    return random_tfs(
        n, seed, gaussians=3, means=(0.3, 0.95), widths=(0.002, 0.01), heights=(0.1, 0.8)
    )


#: The TF the tooth sketch's fit found (benchmarks/sketch_fit.py, seed 0): thin Gaussians on
#: the tooth's surface values.
TOOTH_FIT = GaussianTF(
    (
        Gaussian(mean=0.617, width=0.005, height=0.104, color=(0.16, 0.31, 0.86)),
        Gaussian(mean=0.697, width=0.009, height=0.477, color=(0.94, 0.86, 0.16)),
        Gaussian(mean=0.953, width=0.018, height=0.115, color=(0.86, 0.12, 0.12)),
    )
)


def bench_preintegration(quick: bool) -> None:
    from skimage.color import deltaE_ciede2000, rgb2lab

    n = 4 if quick else 12
    cam = Camera(azimuth=30, elevation=10)
    new_cam = Camera(azimuth=75, elevation=-10)
    sets = {"tooth fit": [TOOTH_FIT], "thin": _thin_tfs(n), "random": random_tfs(n)}
    print("\n== pre-integrated against post-classified: mean CIEDE2000 to a 10x finer picture")
    for file in ("tooth_103x94x161_uint8.raw.gz", "foot_zfp8lossy_256x256x256_uint8.raw.gz"):
        vol = load_volume(DATA / file)
        name = file.split("_")[0]
        ref_r = VolumeRenderer(vol, size=256, sample_distance=0.05, preintegrated=False)
        modes = {
            "post 0.5": VolumeRenderer(vol, size=256, preintegrated=False),
            "pre 0.5": VolumeRenderer(vol, size=256),
            "post 0.25": VolumeRenderer(vol, size=256, sample_distance=0.25, preintegrated=False),
            "pre 1.0": VolumeRenderer(vol, size=256, sample_distance=1.0),
        }
        for label, tfs in sets.items():
            if name == "foot" and label == "tooth fit":
                continue
            refs = [rgb2lab(ref_r.render(tf, cam) / 255.0) for tf in tfs]
            cells = []
            for mode, r in modes.items():
                cache = r.sample_cache(cam)
                cache.render(tfs[0])
                r.render(tfs[0], new_cam)
                errs, per, full = [], [], []
                for tf, ref in zip(tfs, refs, strict=True):
                    t, img = timed(lambda tf=tf, c=cache: c.render(tf))
                    per.append(t)
                    full.append(timed(lambda tf=tf, r=r: r.render(tf, new_cam))[0])
                    lit = ref[..., 0] > 3
                    errs.append(float(deltaE_ciede2000(rgb2lab(img / 255.0), ref)[lit].mean()))
                cells.append(
                    f"{mode} {np.mean(errs):4.2f} ({statistics.median(per) * 1e3:4.1f} ms,"
                    f" new camera {statistics.median(full) * 1e3:4.0f} ms)"
                )
            print(f"{name:5} {label:9} | " + " | ".join(cells), flush=True)


# ---------------------------------------------------------------------------------------------
# --device cuda
# ---------------------------------------------------------------------------------------------
def gpu_facts() -> tuple[str, float | None]:
    """A line describing the GPU, and its peak memory bandwidth in GB/s (None if unknown)."""
    from numba import cuda

    ctx = cuda.current_context()
    dev = ctx.device
    name = getattr(dev, "name", "Numba's CUDA simulator")
    name = name.decode() if isinstance(name, bytes) else str(name)
    free, total = ctx.get_memory_info()
    try:
        clock_khz = int(dev.MEMORY_CLOCK_RATE)
        bus_bits = int(dev.GLOBAL_MEMORY_BUS_WIDTH)
        peak = 2.0 * clock_khz * 1e3 * bus_bits / 8 / 1e9  # double data rate
    except Exception:  # the simulator, or a binding without these attributes
        peak = None
    sms = getattr(dev, "MULTIPROCESSOR_COUNT", "?")
    line = (
        f"GPU: {name}, compute capability {dev.compute_capability}, {sms} SMs, "
        f"{total / 2**30:.1f} GiB ({free / 2**30:.1f} free)"
    )
    return line, peak


def upsampled_foot(foot):
    """The foot trilinearly upsampled ×2 along each axis: 512³ (a real volume at that size)."""
    from scipy import ndimage

    from intuitf.volume import Volume

    t = time.perf_counter()
    up = ndimage.zoom(foot.data, 2.0, order=1, prefilter=False).astype(np.float32)
    np.clip(up, 0.0, 1.0, out=up)
    vol = Volume(
        data=up,
        spacing=tuple(s / 2 for s in foot.spacing),
        name="foot ×2",
        original_dtype=foot.original_dtype,
        value_range=foot.value_range,
    )
    print(f"foot upsampled to {vol.dims} in {time.perf_counter() - t:.1f} s")
    return vol


def agreement(a: np.ndarray, b: np.ndarray) -> tuple[float, int, float]:
    """(mean |diff| in 8-bit levels, max, PSNR dB) of two uint8 pictures."""
    d = np.abs(a.astype(np.int16) - b.astype(np.int16))
    mse = float(np.mean(d.astype(np.float64) ** 2))
    return float(d.mean()), int(d.max()), 99.0 if mse == 0 else 10 * np.log10(255.0**2 / mse)


def bench_cuda_config(vol, size, shading, tfs, args, peak, vtk_ok) -> dict:
    from numba import cuda

    cam = Camera(azimuth=30, elevation=20)
    new_cam = Camera(azimuth=75, elevation=-10)
    kw = dict(size=size, shading=shading, sample_distance=args.sample_distance)
    gpu = VolumeRenderer(vol, device="cuda", **kw)
    k = len(tfs)
    row: dict = {"volume": vol.name, "dims": vol.dims, "size": size, "shading": shading}
    # Warm up: JIT (or the on-disk kernel cache), volume and gradient upload.
    t = time.perf_counter()
    gpu.render(tfs[0], cam)
    gpu.sample_cache(cam).render_many(tfs[:2])
    row["first_call_s"] = time.perf_counter() - t

    def build():
        c = gpu.sample_cache(cam)
        cuda.synchronize()
        return c

    row["build_ms"], cache = timed(build, repeat=3)
    row["build_ms"] *= 1e3
    row["cache_mb"] = cache.nbytes / 1e6
    row["samples_m"] = cache.n_samples / 1e6
    # A population end to end: LUTs on the host, upload, one launch, 8-bit pictures back.
    t_pop, pics = timed(lambda: cache.render_many(tfs), repeat=args.repeat)
    row["per_cand_ms"] = t_pop / k * 1e3
    t_lut, _ = timed(lambda: [gpu.classification(tf) for tf in tfs], repeat=3)
    row["lut_ms"] = t_lut / k * 1e3
    # The kernel alone, timed with CUDA events.
    parts = cache.upload(tfs)
    times = []
    for _ in range(args.repeat):
        start, stop = cuda.event(), cuda.event()
        start.record()
        for kk, luts, tables, occ in parts:
            cache.launch(kk, luts, tables, occ)
        stop.record()
        stop.synchronize()
        times.append(start.elapsed_time(stop))
    row["kernel_us"] = statistics.median(times) / k * 1e3
    # New camera, one TF: direct marching with the TF's skipping (interactive views).
    row["new_cam_ms"] = (
        statistics.median(timed(lambda t=t: gpu.render(t, new_cam))[0] for t in tfs[:10]) * 1e3
    )
    # Bandwidth: the bytes of the cache each candidate reads, against the GPU's peak.
    read = cache.bytes_read(tfs[:8])
    row["read_mb"] = float(read.mean()) / 1e6
    if peak:
        row["bw_floor_us"] = row["read_mb"] * 1e6 / (peak * 1e9) * 1e6
        if row["kernel_us"] > 0:  # (the simulator's events time nothing)
            row["bw_pct"] = 100.0 * row["bw_floor_us"] / row["kernel_us"]
    # The CPU path on this machine, and the agreement of the pictures.
    n_cpu = min(args.cpu_candidates, k)
    if n_cpu:
        cpu = VolumeRenderer(vol, device="cpu", **kw)
        cpu.sample_cache(cam).render(tfs[0])  # JIT, gradient
        t_cb, ccache = timed(lambda: cpu.sample_cache(cam))
        row["cpu_build_ms"] = t_cb * 1e3
        per = [timed(lambda t=t: ccache.render(t))[0] for t in tfs[:n_cpu]]
        row["cpu_ms"] = statistics.median(per) * 1e3
        row["cpu_new_cam_ms"] = (
            statistics.median(timed(lambda t=t: cpu.render(t, new_cam))[0] for t in tfs[:3]) * 1e3
        )
        stats = [agreement(pics[i], ccache.render(tfs[i])) for i in range(n_cpu)]
        row["agree_mean"] = max(s[0] for s in stats)
        row["agree_max"] = max(s[1] for s in stats)
        row["agree_psnr"] = min(s[2] for s in stats)
        d = agreement(gpu.render(tfs[0], new_cam), cpu.render(tfs[0], new_cam))
        row["march_agree"] = d
        a_gpu, a_cpu = cache.attribution(tfs[0]), ccache.attribution(tfs[0])
        row["attr_maxdiff"] = float(np.abs(a_gpu - a_cpu).max())
        del ccache, cpu
    if vtk_ok:
        from helpers.vtkref import VTKScene

        ref = VolumeRenderer(vol, device="cpu", **kw)
        scene = VTKScene(ref, "gpu")
        scene.render(tfs[0], cam)
        tv = [timed(lambda t=t: scene.render(t, cam))[0] for t in tfs[: min(20, k)]]
        row["vtk_gpu_ms"] = statistics.median(tv) * 1e3
        scene.close()
    return row


def write_json(path: str | None, record: dict) -> None:
    """Append ``record`` as one JSON line to ``path`` (--json), as soon as it is measured."""
    if not path:
        return
    import json

    def plain(v):
        if isinstance(v, (tuple, list)):
            return [plain(x) for x in v]
        return v.item() if isinstance(v, np.generic) else v

    with open(path, "a", encoding="utf-8") as f:
        f.write(json.dumps({k: plain(v) for k, v in record.items()}) + "\n")


def speedup(a: float, b: float) -> str:
    """``a / b`` as a speed-up factor."""
    x = a / b
    return f"{x:.0f}×" if x >= 10 else f"{x:.1f}×"


def print_row(r: dict) -> None:
    shade = "shaded  " if r["shading"] else "unshaded"
    line = (
        f"{r['volume']} {shade} {r['size']}²: build {r['build_ms']:.1f} ms "
        f"({r['cache_mb']:.1f} MB GPU, {r['samples_m']:.1f} M samples) | per candidate "
        f"{r['per_cand_ms']:.3f} ms end to end (kernel {r['kernel_us']:.0f} µs, host LUTs "
        f"{r['lut_ms'] * 1e3:.0f} µs) | new camera {r['new_cam_ms']:.1f} ms"
    )
    if "bw_pct" in r:
        line += (
            f" | reads {r['read_mb']:.1f} MB/candidate: bandwidth floor {r['bw_floor_us']:.0f} µs,"
            f" kernel at {r['bw_pct']:.0f}% of peak"
        )
    if "cpu_ms" in r:
        m = r["march_agree"]
        line += (
            f" | CPU {r['cpu_ms']:.1f} ms/candidate ({speedup(r['cpu_ms'], r['per_cand_ms'])}), "
            f"build {r['cpu_build_ms']:.0f} ms, new camera {r['cpu_new_cam_ms']:.0f} ms"
            f" | agreement cache: mean ≤ {r['agree_mean']:.2f}/255, max {r['agree_max']},"
            f" PSNR ≥ {r['agree_psnr']:.1f} dB; march: {m[0]:.2f}/255, max {m[1]},"
            f" {m[2]:.1f} dB; attribution max diff {r['attr_maxdiff']:.1e}"
        )
    if "vtk_gpu_ms" in r:
        line += f" | VTK GPU mapper {r['vtk_gpu_ms']:.1f} ms ({speedup(r['vtk_gpu_ms'], r['per_cand_ms'])})"
    print(line, flush=True)


def cuda_main(args) -> None:
    import numba

    from intuitf.render.device import cuda_unavailable_reason

    reason = cuda_unavailable_reason()
    if reason is not None:
        sys.exit(f"--device cuda: no usable NVIDIA GPU here ({reason}); nothing was measured.")
    line, device_peak = gpu_facts()
    peak = args.peak_bandwidth or device_peak
    from numba import cuda

    print(line)
    print(
        f"numba {numba.__version__}, numba.cuda {getattr(cuda, 'implementation', '?')}; "
        f"peak memory bandwidth {f'{peak:.0f} GB/s' if peak else 'unknown (--peak-bandwidth)'}"
        f" (from the device's memory clock and bus: "
        f"{f'{device_peak:.0f} GB/s' if device_peak else 'not reported'});"
        f" {os.cpu_count()} CPUs, numba {numba.get_num_threads()} threads"
    )
    vtk_ok = not args.no_vtk
    if vtk_ok:
        from helpers.vtkref import vtk_available

        why = vtk_available()
        if why:
            print(f"VTK GPU baseline skipped: {why}")
            vtk_ok = False
        else:
            import vtk

            win = vtk.vtkRenderWindow()
            win.SetOffScreenRendering(1)
            win.Render()
            caps = win.ReportCapabilities() or ""
            gl = [
                ln.split(":", 1)[1].strip() for ln in caps.splitlines() if "renderer string" in ln
            ]
            win.Finalize()
            print(
                f"VTK {vtk.vtkVersion.GetVTKVersion()} renders with OpenGL on: {gl[0] if gl else '?'}"
            )
    tfs = random_tfs(args.population)
    sizes = [int(v) for v in args.sizes.split(",") if v]
    rows = []
    foot = None
    for key in [v for v in args.volumes.split(",") if v]:
        if key.startswith("phantom"):  # phantom:N, e.g. for a smoke run under the simulator
            vol = phantom(size=int(key.partition(":")[2] or 160))
        else:
            if foot is None:
                foot = load_volume(DATA / "foot_zfp8lossy_256x256x256_uint8.raw.gz")
            vol = foot if key == "foot" else upsampled_foot(foot)
        print(
            f"\n== {vol.name} {vol.dims}: population {len(tfs)} random 5-Gaussian TFs, az 30 el 20"
        )
        for shading in (False, True):
            for size in sizes:
                row = bench_cuda_config(vol, size, shading, tfs, args, peak, vtk_ok)
                print_row(row)
                write_json(args.json, {"kind": "render", "gpu": line, "peak_gbs": peak, **row})
                rows.append(row)
    print(
        "\n| volume | picture | shading | ms/candidate (kernel µs) | build ms | new camera ms |"
        " % of bandwidth | CPU ms/candidate | VTK GPU ms |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['volume']} | {r['size']}² | {'yes' if r['shading'] else 'no'} | "
            f"{r['per_cand_ms']:.3f} ({r['kernel_us']:.0f}) | {r['build_ms']:.1f} | "
            f"{r['new_cam_ms']:.1f} | {r.get('bw_pct', float('nan')):.0f} | "
            f"{r.get('cpu_ms', float('nan')):.1f} | {r.get('vtk_gpu_ms', float('nan')):.1f} |"
        )
    print(
        "\nTargets (issue 12, H100, population 50): under 0.2 ms per candidate at 256² and under"
        " 1 ms at 512², shaded; a new-camera shaded 512² render under 10 ms. 'Reads' counts the"
        " cache bytes each candidate's compositing loads (after skipping and early stopping);"
        " the bandwidth floor is that over the peak, so 100% would mean every candidate streamed"
        " its bytes from memory at peak (L2 reuse among the population can beat it)."
    )


def generation_main(args) -> None:
    """A generation's rendering as ``intuitf optimize`` does it: a Session on the 256³ foot
    (population ``--population``, judging pictures ``--gen-size``², shaded, the metric judge
    against a fixed reference picture), timing the render jobs of each generation through
    :meth:`Session.on_render` (the sample cache for the judging camera and the candidates'
    pictures; on the GPU the population is one launch). Generation 0 includes the JIT and
    the gradient; later ones are the steady state. Threads for the CPU path: set
    ``NUMBA_NUM_THREADS`` (2 for the two-core comparison)."""
    import numba

    from intuitf.evaluator.types import Intent
    from intuitf.render.device import select_device
    from intuitf.session import RunSettings, Session

    device = select_device(args.device)
    vol = load_volume(DATA / "foot_zfp8lossy_256x256x256_uint8.raw.gz")
    n = args.gen_size
    yy, xx = np.mgrid[0:n, 0:n] / max(n - 1, 1)  # a smooth reference picture: the judge's input
    reference = (np.stack([xx, yy, 0.5 * (xx + yy)], axis=-1) * 255).astype(np.uint8)
    settings = RunSettings(
        population=args.population,
        generations=args.generations,
        image_size=n,
        shading=True,
        device=device,
        seed=1,
    )
    session = Session.create(
        vol, intent=Intent(kind="image", reference=reference), settings=settings
    )
    jobs: list[float] = []
    session.on_render(jobs.append)
    threads = numba.get_num_threads()
    print(
        f"generation timing: device {device}, foot {vol.dims}, population {args.population},"
        f" {n}² shaded; numba {threads} CPU threads"
    )
    try:
        for g in range(args.generations):
            jobs.clear()
            t = time.perf_counter()
            session.step()
            wall = time.perf_counter() - t
            render = sum(jobs)
            print(
                f"generation {g}: rendering {render * 1e3:.1f} ms in {len(jobs)} jobs"
                f" ({render / args.population * 1e3:.2f} ms/candidate), whole step {wall:.2f} s",
                flush=True,
            )
            write_json(
                args.json,
                {
                    "kind": "generation", "device": device, "generation": g,
                    "population": args.population, "size": n, "threads": threads,
                    "render_ms": render * 1e3, "jobs": len(jobs), "step_s": wall,
                },
            )  # fmt: skip
    finally:
        session.close()


def ptx_report(arch: str) -> None:
    """Compile every CUDA kernel for ``arch`` (no GPU needed) and print registers and spills."""
    import re
    import shutil
    import subprocess
    import tempfile

    from intuitf.render.cuda_compat import prepare_numba_cuda

    prepare_numba_cuda()
    import numba.cuda.dispatcher as dispatcher
    from numba import cuda
    from numba import types as t

    digits = arch.removeprefix("sm_").removeprefix("compute_")
    cc = (int(digits[:-1]), int(digits[-1]))  # sm_90 -> (9, 0), sm_120 -> (12, 0)

    class _Device:  # device functions ask for the current device's compute capability
        compute_capability = cc

    dispatcher.get_current_device = lambda: _Device()
    from intuitf.render import cuda_kernels as ck

    f32, f64, i32, i64 = t.float32, t.float64, t.int32, t.int64
    b, u8, i16 = t.boolean, t.uint8, t.int16

    def arr(dt, nd):
        return t.Array(dt, nd, "C")

    sigs = {
        "march": (arr(f32, 3), arr(i16, 4), b, arr(u8, 4), i64, arr(f32, 3), b, arr(f32, 1),
                  arr(f32, 1), f32, arr(f32, 1), f32, i64, arr(f32, 1), b, arr(f32, 3),
                  arr(u8, 3)),
        "count_samples": (arr(f64, 1), arr(f64, 1), i64, i64, i64, f64, i64, arr(i32, 1),
                          arr(f64, 1)),
        "fill_samples": (arr(f32, 3), arr(i16, 4), b, arr(f64, 1), arr(f64, 1), f64, i64, f64,
                         i64, arr(i32, 1), arr(f64, 1), arr(i64, 1), arr(u8, 1), arr(u8, 1),
                         arr(u8, 1), arr(u8, 1), arr(u8, 1)),
        "composite": (arr(i32, 1), arr(i64, 1), arr(u8, 1), arr(u8, 1), arr(u8, 1), arr(u8, 1),
                      arr(u8, 1), arr(i32, 2), arr(f32, 3), b, arr(f32, 1), f32, i64, i64, i64,
                      arr(f32, 1), b, arr(f32, 3), arr(u8, 3)),
        "count_reads": (arr(i32, 1), arr(i64, 1), arr(u8, 1), arr(u8, 1), arr(u8, 1),
                        arr(i32, 2), arr(f32, 2), f32, i64, i64, i64, arr(i32, 3)),
        "attribute": (arr(i32, 1), arr(i64, 1), arr(u8, 1), arr(u8, 1), arr(u8, 1), arr(i32, 1),
                      arr(f32, 1), arr(f32, 2), f32, i64, i64, i64, arr(f32, 2)),
    }  # fmt: skip
    ptxas = shutil.which("ptxas")
    if ptxas is None:
        try:
            import nvidia.cuda_nvcc as nvcc

            cand = Path(list(nvcc.__path__)[0]) / "bin" / "ptxas"
            ptxas = str(cand) if cand.exists() else None
        except ImportError:
            ptxas = None
    with tempfile.TemporaryDirectory() as tmp:
        for name, sig in sigs.items():
            ptx, _ = cuda.compile_ptx(getattr(ck, name).py_func, sig, cc=cc, fastmath=True)
            n64 = sum(1 for ln in ptx.splitlines() if ".f64" in ln and "//" not in ln)
            info = ""
            if ptxas:
                path = Path(tmp) / f"{name}.ptx"
                path.write_text(ptx)
                res = subprocess.run(
                    [ptxas, f"-arch={arch}", "-v", str(path), "-o", os.devnull],
                    capture_output=True,
                    text=True,
                )
                info = " ".join(re.findall(r"Used \d+ registers|\d+ bytes spill \w+", res.stderr))
            print(f"{name}: {n64} float64 instructions; {info or '(no ptxas found)'}")


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
    ap.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        default="cpu",
        help="cpu: the CPU path against VTK's fixed-point mapper (default); cuda: the GPU backend "
        "against the CPU path and VTK's GPU ray caster",
    )
    ap.add_argument("--population", type=int, default=50, help="--device cuda: TFs per launch")
    ap.add_argument("--sizes", default="256,512,1024", help="--device cuda: picture sizes")
    ap.add_argument(
        "--volumes",
        default="foot,foot512",
        help="--device cuda: foot (256³), foot512 (the foot upsampled ×2), phantom:N",
    )
    ap.add_argument(
        "--cpu-candidates",
        type=int,
        default=10,
        help="--device cuda: TFs the CPU baseline renders per configuration (0: skip it)",
    )
    ap.add_argument(
        "--peak-bandwidth",
        type=float,
        default=None,
        help="GPU memory bandwidth in GB/s (default: from the device's memory clock and bus width)",
    )
    ap.add_argument("--repeat", type=int, default=5, help="--device cuda: timed launches")
    ap.add_argument(
        "--ptx", metavar="ARCH", default=None, help="compile the CUDA kernels for ARCH (e.g. sm_90)"
    )
    ap.add_argument(
        "--generation",
        action="store_true",
        help="time a generation's rendering through a Session (the optimiser's path) on --device",
    )
    ap.add_argument("--generations", type=int, default=3, help="--generation: generations to run")
    ap.add_argument("--gen-size", type=int, default=256, help="--generation: judging picture size")
    ap.add_argument("--json", default=None, help="append each measured row as a JSON line here")
    ap.add_argument(
        "--preintegration",
        action="store_true",
        help="pre-integrated against post-classified pictures: quality and time",
    )
    args = ap.parse_args()
    if args.preintegration:
        bench_preintegration(args.quick)
        return
    if args.ptx:
        ptx_report(args.ptx)
        return
    if args.generation:
        generation_main(args)
        return
    if args.device == "cuda":
        cuda_main(args)
        return
    tfs = random_tfs(10 if args.quick else 50)
    use_vtk = not args.no_vtk
    if use_vtk:
        from helpers.vtkref import vtk_available

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
