"""The CUDA backend, checked without a GPU.

CI has no GPU, so the CUDA kernels run under Numba's CUDA simulator, which executes them as
Python on the CPU. The simulator must be switched on before ``numba.cuda`` is first imported,
and this test process has imported it already (or may), so the checks run in a subprocess:
this file executed as a script with ``NUMBA_ENABLE_CUDASIM=1``. On tiny volumes and pictures
the CUDA kernels' pictures, attribution and picks are compared with the CPU kernels'. A
change that breaks the CUDA kernels fails here, never skips. The full-size agreement and
speed are measured on a GPU machine by ``benchmarks/render.py --device cuda``.

The other tests check device selection where there is no GPU: ``auto`` falls back to the CPU
silently, ``cuda`` is a one-line error with a hint (from the API and from the command line).
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from intuitf.errors import IntuitfError, RenderError
from intuitf.render.device import cuda_unavailable_reason, select_device


def test_cuda_kernels_agree_with_the_cpu_kernels_under_the_simulator():
    env = dict(os.environ, NUMBA_ENABLE_CUDASIM="1")
    proc = subprocess.run(
        [sys.executable, __file__], env=env, capture_output=True, text=True, timeout=900
    )
    report = proc.stdout[-6000:] + proc.stderr[-6000:]
    assert proc.returncode == 0, report
    assert "simulator checks passed" in proc.stdout, report


def test_auto_uses_the_cpu_where_no_gpu_is_usable():
    expected = "cpu" if cuda_unavailable_reason() is not None else "cuda"
    assert select_device("auto") == expected
    assert select_device("cpu") == "cpu"
    with pytest.raises(RenderError, match="Unknown render device"):
        select_device("tpu")


def test_asking_for_cuda_without_a_gpu_is_a_clear_error():
    if cuda_unavailable_reason() is None:
        pytest.skip("a GPU is usable here")
    with pytest.raises(RenderError) as exc:
        select_device("cuda")
    assert "no NVIDIA GPU can be used here" in exc.value.message
    assert "\n" not in exc.value.message
    assert "--device cpu" in exc.value.hint and "intuitf[cuda]" in exc.value.hint


def test_render_command_with_device_cuda_and_no_gpu_says_so_in_one_line(tmp_path, capsys):
    if cuda_unavailable_reason() is None:
        pytest.skip("a GPU is usable here")
    from intuitf.cli.app import main

    out = tmp_path / "p.png"
    with pytest.raises(SystemExit) as exc:
        main(["render", "phantom", "--size", "32", "--device", "cuda", "-o", str(out)])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "no NVIDIA GPU can be used here" in err and "Traceback" not in err
    assert not out.exists()
    main(["render", "phantom", "--size", "32", "--device", "auto", "-o", str(out)])
    assert out.exists()


def test_run_settings_take_a_device():
    from intuitf.session.settings import RunSettings

    assert RunSettings().device == "auto"
    RunSettings(device="cpu").validate()
    with pytest.raises(IntuitfError, match="--device"):
        RunSettings(device="gpu").validate()
    assert RunSettings.from_dict(RunSettings(device="cuda").to_dict()).device == "cuda"


# ---------------------------------------------------------------------------------------------
# Run as a script under the simulator
# ---------------------------------------------------------------------------------------------
def _volumes():
    from intuitf.volume import Volume

    rng = np.random.default_rng(3)
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, n) for n in (14, 13, 12)), indexing="ij")
    r = np.sqrt(x**2 + (1.2 * y) ** 2 + (0.9 * z) ** 2)
    shell = np.clip(1.0 - np.abs(r - 0.75) * 6, 0, 1) * 200
    core = np.clip(1.0 - r * 2.2, 0, 1) * 120 + 40 * (x > 0.3)
    u8 = np.clip(shell + core + rng.normal(0, 6, r.shape), 0, 255).astype(np.uint8)
    yield Volume.from_array(u8, spacing=(1.0, 1.2, 0.8), name="u8-12x13x14")
    # 16-bit values: more than 256 LUT entries, so uint16 samples in the cache.
    u16 = (u8.astype(np.uint16) * 7 + rng.integers(0, 7, u8.shape)).astype(np.uint16)
    yield Volume.from_array(u16[:12, :12, :12].copy(), name="u16-12^3")
    # Float values between the shading voxels' 65536 value codes: a shaded sample's value is
    # read from the codes, and must land on the CPU's LUT entry all the same.
    f32 = (u16[:12, :12, :12] / 1791.0 + rng.uniform(0, 0.01, (12, 12, 12))).astype(np.float32)
    yield Volume.from_array(f32, name="f32-12^3")


def _tfs(n: int, seed: int):
    from intuitf.tf import Gaussian, GaussianTF

    rng = np.random.default_rng(seed)
    return [
        GaussianTF(
            tuple(
                Gaussian(
                    mean=float(rng.uniform(0.1, 0.95)),
                    # One narrow Gaussian per TF: thinner than the values' step between
                    # samples, what pre-integration is for.
                    width=float(rng.uniform(0.03, 0.15)) if g else 0.004,
                    height=float(rng.uniform(0.05, 0.9)),
                    color=tuple(float(c) for c in rng.uniform(0, 1, 3)),
                )
                for g in range(3)
            )
        )
        for _ in range(n)
    ]


def _gpu_samples_by_pixel(gpu_cache) -> list[np.ndarray]:
    """The GPU cache's LUT entries per ray, in the CPU cache's pixel order (row-major)."""
    from intuitf.render import cuda_kernels as ck

    be = gpu_cache.backend
    counts = gpu_cache.counts.copy_to_host()
    base = gpu_cache.tile_base.copy_to_host()
    samples = gpu_cache.samples.copy_to_host()
    width, height = gpu_cache.renderer.width, gpu_cache.renderer.height
    rays: list[np.ndarray] = [np.empty(0, samples.dtype)] * (width * height)
    for slot in range(be.n_slots):
        tile, lane = divmod(slot, ck.WARP)
        ty, tx = divmod(tile, be.tiles_x)
        i, j = ty * ck.TILE_H + lane // ck.TILE_W, tx * ck.TILE_W + lane % ck.TILE_W
        if i < height and j < width:
            rays[i * width + j] = samples[base[tile] + lane + ck.WARP * np.arange(counts[slot])]
    return rays


def _bytes_read_reference(cpu_cache, renderer, tfs) -> np.ndarray:
    """What the GPU composite reads per TF, from the CPU cache's samples: per ray, runs of 32
    samples from its start, skipped when the LUT is empty over the run's value range."""
    item = cpu_cache.samples.dtype.itemsize
    per_sample = item + (2 if renderer.shading else 0)
    out = []
    for tf in tfs:
        cls = renderer.classification(tf)
        alpha, occ = cls.lut[:, 3], cls.occupied
        total = 0
        for p in range(len(cpu_cache.offsets) - 1):
            ray = cpu_cache.samples[cpu_cache.offsets[p] : cpu_cache.offsets[p + 1]]
            tr = np.float32(1.0)
            for s in range(0, len(ray), 32):
                seg = ray[s : s + 32]
                total += 2 * item
                if occ[int(seg.max()) + 1] == occ[int(seg.min())]:
                    continue
                stop = False
                for q in seg:
                    total += per_sample
                    if alpha[q] > 0:
                        tr = np.float32(tr * (np.float32(1.0) - alpha[q]))
                        if tr < np.float32(1.0 / 255.0):
                            stop = True
                            break
                if stop:
                    break
        out.append(total)
    return np.array(out, dtype=np.int64)


class Checks:
    """Collects named pass/fail checks, printing each, so one run reports every failure."""

    def __init__(self) -> None:
        self.failures: list[str] = []

    def __call__(self, ok: bool, what: str) -> None:
        print(("ok   " if ok else "FAIL ") + what, flush=True)
        if not ok:
            self.failures.append(what)

    def rgb(self, name: str, a: np.ndarray, b: np.ndarray, max_levels: int | None = 2) -> None:
        """8-bit pictures: the VTK tests' tolerance (mean under 2/255, PSNR over 40 dB), tighter
        where asked (mean under 0.5/255, no pixel more than ``max_levels`` apart)."""
        d = np.abs(a.astype(np.int16) - b.astype(np.int16))
        mse = float(np.mean(d.astype(np.float64) ** 2))
        psnr = 99.0 if mse == 0 else 10 * np.log10(255.0**2 / mse)
        ok = a.shape == b.shape and d.mean() < 2.0 and psnr > 40
        if max_levels is not None:
            ok = ok and d.mean() < 0.5 and d.max() <= max_levels
        self(ok, f"{name}: mean {d.mean():.3f}/255, max {d.max()}, PSNR {psnr:.1f} dB")

    def close(self, name: str, a: np.ndarray, b: np.ndarray, tol: float = 4e-3) -> None:
        # float32 on the GPU, float64 in parts of the CPU kernels: a value on a rounding
        # boundary may land on the neighbouring LUT entry, moving a pixel by well under 1/255.
        d = np.abs(a - b)
        ok = a.shape == b.shape and d.max() < tol and d.mean() < 2e-4
        self(ok, f"{name}: max |diff| {d.max():.2e}, mean {d.mean():.1e}")


CAMERAS = {
    "orthographic": dict(azimuth=30, elevation=20, projection="orthographic"),
    "perspective": dict(azimuth=-65, elevation=35, roll=10, zoom=1.3, pan=(0.05, -0.1)),
}


def _compare(
    check: Checks, vol, cam_name: str, size, shading: bool, strict: bool, walk: bool = True,
    levels: int | None = None, march_tol: float = 4e-3, preintegrated: bool = True,
) -> None:  # fmt: skip
    """GPU (device="cuda") against CPU pictures, caches, attribution, picks, feature views.

    ``strict``: 8-bit pixels at most ``levels`` (default 2) apart, float pictures within 4e-3
    (``march_tol`` for the direct marcher's); ``walk``: also check the bytes the GPU composite
    reads against a reference that walks every ray in Python (for tiny pictures only)."""
    from intuitf.render import Camera, VolumeRenderer
    from intuitf.render.cuda_backend import CudaSampleCache
    from intuitf.tf import Gaussian, GaussianTF

    cam = Camera(**CAMERAS[cam_name])
    if levels is None:
        levels = 2 if strict else None
    tol = 4e-3 if strict else 2e-2
    tag = f"{vol.name} {cam_name} {'shaded' if shading else 'unshaded'}"
    if not preintegrated:
        tag += " post-classified"
    kw = dict(size=size, shading=shading, background=(0.1, 0.2, 0.3), preintegrated=preintegrated)
    cpu = VolumeRenderer(vol, device="cpu", **kw)
    gpu = VolumeRenderer(vol, device="cuda", **kw)
    check(gpu.device == "cuda" and cpu.device == "cpu", f"{tag}: devices")
    tfs = _tfs(3, seed=len(tag))
    # Direct ray marching: float RGBA and 8-bit, interpolated and nearest LUT.
    if strict:
        check.close(
            f"{tag} march rgba",
            gpu.render_rgba(tfs[0], cam),
            cpu.render_rgba(tfs[0], cam),
            march_tol,
        )
        check.close(
            f"{tag} march nearest",
            gpu.render_rgba(tfs[1], cam, nearest=True),
            cpu.render_rgba(tfs[1], cam, nearest=True),
            march_tol,
        )
    check.rgb(f"{tag} march rgb8", gpu.render(tfs[2], cam), cpu.render(tfs[2], cam), levels)
    invisible = GaussianTF((Gaussian(mean=0.99, width=0.002, height=1e-9, color=(1, 0, 0)),))
    empty = gpu.render(invisible, cam)
    check(
        bool(np.all(empty == empty[0, 0]) and np.all(empty == cpu.render(invisible, cam))),
        f"{tag}: invisible TF gives the background",
    )
    # Sample cache: same samples, a population in one launch.
    gc = gpu.sample_cache(cam)
    cc = cpu.sample_cache(cam)
    check(isinstance(gc, CudaSampleCache), f"{tag}: GPU cache type")
    check(
        abs(gc.n_samples - cc.n_samples) <= max(2, cc.n_samples // 200),
        f"{tag}: samples {gc.n_samples} (GPU) vs {cc.n_samples} (CPU)",
    )
    check(gc.samples.dtype == cc.samples.dtype, f"{tag}: sample dtype")
    if strict:  # the build follows the CPU's float64 arithmetic: the same LUT entries
        rays = _gpu_samples_by_pixel(gc)
        cpu_rays = np.split(cc.samples, cc.offsets[1:-1])
        same = [
            len(a) == len(b) and np.array_equal(a, b) for a, b in zip(rays, cpu_rays, strict=True)
        ]
        check(
            all(same), f"{tag}: LUT entries of the cache's samples, {same.count(False)} rays differ"
        )
    many = gc.render_many(tfs)
    check(len(many) == 3, f"{tag}: render_many returns one picture per TF")
    for k, (img, tf) in enumerate(zip(many, tfs, strict=True)):
        check.rgb(f"{tag} cache candidate {k}", img, cc.render(tf), levels)
        check(np.array_equal(img, gc.render(tf)), f"{tag}: batch = single ({k})")
    check.close(f"{tag} cache rgba", gc.render_rgba(tfs[1]), cc.render_rgba(tfs[1]), tol)
    check.close(
        f"{tag} cache vs march nearest",
        gc.render_rgba(tfs[2]),
        gpu.render_rgba(tfs[2], cam, nearest=True),
        max(tol, march_tol) + (2e-3 if shading else 0.0),  # shading terms rounded to 1/255
    )
    if strict and walk:  # the reference walks every ray in Python
        expected = _bytes_read_reference(cc, gpu, tfs)
        got = gc.bytes_read(tfs)
        check(
            bool(np.all(np.abs(got - expected) <= 0.02 * expected + 64)),
            f"{tag}: bytes read {got.tolist()} vs {expected.tolist()} (reference)",
        )
    rmany = gpu.render_many(tfs, cam)
    check(
        all(np.array_equal(a, b) for a, b in zip(rmany, many, strict=True)),
        f"{tag}: renderer.render_many",
    )
    # Attribution, picking and feature views.
    check.close(f"{tag} attribution", gc.attribution(tfs[0]), cc.attribution(tfs[0]), tol)
    alpha = cc.render_rgba(tfs[0])[..., 3]
    ys, xs = np.nonzero(alpha > 0.05)
    at = np.linspace(0, len(xs) - 1, 6).astype(int) if len(xs) else []
    for x, y in [(int(xs[i]), int(ys[i])) for i in at] + [(0, 0)]:
        for radius in (0, 2):
            pg = gc.pick(tfs[0], x, y, radius=radius)
            pc = cc.pick(tfs[0], x, y, radius=radius)
            same = [i for i, _ in pg] == [i for i, _ in pc] and all(
                abs(a - b) < 1e-3 for (_, a), (_, b) in zip(pg, pc, strict=True)
            )
            check(same, f"{tag}: pick ({x}, {y}) r={radius}: {pg} vs {pc}")
    check.rgb(
        f"{tag} feature view",
        gc.render_feature(tfs[0], [0, 2]),
        cc.render_feature(tfs[0], [0, 2]),
        levels,
    )


def _simulator_checks() -> None:
    from numba.core import config

    assert config.ENABLE_CUDASIM, "run with NUMBA_ENABLE_CUDASIM=1 set before numba is imported"
    assert select_device("cuda") == "cuda"
    assert select_device("auto") == "cpu", "auto must never pick the simulator"
    check = Checks()
    sizes = {"orthographic": 16, "perspective": (13, 10)}  # 13×10: partial 8×4 tiles
    for vol in _volumes():
        for cam_name, size in sizes.items():
            for shading in (False, True):
                _compare(check, vol, cam_name, size, shading, strict=True)
    # Each sample by its own value (VTK's classification): the same agreement.
    u8 = next(iter(_volumes()))
    for shading in (False, True):
        _compare(check, u8, "perspective", sizes["perspective"], shading, strict=True,
                 preintegrated=False)  # fmt: skip
    if check.failures:
        print(f"{len(check.failures)} simulator check(s) failed")
        sys.exit(1)
    print("simulator checks passed")


# ---------------------------------------------------------------------------------------------
# On an NVIDIA GPU (skipped without one): the same checks on real volumes
# ---------------------------------------------------------------------------------------------
# benchmarks/gpu_check.sh runs these with -s, so every check's figures land in its log.
# Measured on an H200 (benchmarks/gpu_results/): every 8-bit picture within 1 level of the
# CPU's, every pick identical, attribution within 1.3e-3. The direct marcher runs float32
# perspective rays, which put single pixels of the float RGBA up to 5e-3 (1.3/255; mean 4e-7)
# from the CPU's float64 ones, hence its 6e-3 here.
@pytest.mark.skipif(cuda_unavailable_reason() is not None, reason="no usable NVIDIA GPU")
@pytest.mark.parametrize("volume_name", ["foot", "tooth", "neghip"])
@pytest.mark.parametrize("cam_name", list(CAMERAS))
@pytest.mark.parametrize("shading", [False, True], ids=["unshaded", "shaded"])
def test_gpu_agrees_with_cpu_on_real_volumes(volume_name, cam_name, shading, request):
    check = Checks()
    vol = request.getfixturevalue(volume_name)
    _compare(check, vol, cam_name, 128, shading, strict=True, walk=False, levels=1, march_tol=6e-3)
    assert not check.failures, "\n".join(check.failures)


if __name__ == "__main__":
    _simulator_checks()
