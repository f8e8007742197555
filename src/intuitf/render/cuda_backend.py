"""The CUDA backend of :class:`VolumeRenderer` (``device="cuda"``), written with ``numba.cuda``.

Selected by ``VolumeRenderer(volume, device="auto" | "cpu" | "cuda")`` (see
:func:`intuitf.render.device.select_device`); the interface is the CPU one:
``renderer.render(tf, camera)`` / ``render_rgba`` ray-march directly, ``renderer.sample_cache
(camera)`` returns a :class:`CudaSampleCache` with ``render``, ``render_rgba``,
``render_many``, ``attribution``, ``pick`` and ``render_feature``, and
``renderer.render_many(tfs, camera)`` renders a whole population. Kernels are in
:mod:`.cuda_kernels`; they take the CPU kernels' samples at the same positions with the same
arithmetic (in float32), so pictures agree with the CPU's within float rounding.

What lives where
----------------
- The volume (float32) and, for shading, its shading voxels (int16 central-difference
  gradient and value code) are copied to the GPU once per :class:`~intuitf.volume.Volume`
  and shared by every renderer of it (a renderer per picture size, as the Session keeps).
  They are computed by the CPU kernels, so they are bit-identical to the CPU path's, and a
  shaded sample reads its value from the codes on both (a 16-bit volume's values otherwise
  land a few per million on the neighbouring LUT entry).
- A population's LUTs (K, L, 4), their occupancy prefix sums (K, L + 1) and, for direct
  marching, their visible-block masks go up together, and the population renders in one
  launch: one thread per (ray, candidate), the K candidates of a block of rays side by side so
  that they share what they read through L2 (see the :mod:`.cuda_kernels` docstring).
- Pictures come back as 8-bit RGB composited over the background on the GPU (3 bytes per
  pixel, not 16): at 512² a population of 50 is 39 MB over PCIe rather than 210 MB.

Direct marching or a sample cache on the GPU?
---------------------------------------------
Both are here, used as on the CPU, because they win in different places:

- **A population (render_many, the optimiser's generations) uses a GPU sample cache.**
  Marching the volume per candidate costs 8 scattered float32 loads and 8 float multiply-adds
  per sample for the value (int16 codes when shaded), plus 24 int16 loads for the gradient
  when shaded, with no
  texture hardware behind ``numba.cuda``; the cache turns this into 1 byte (unshaded) or 3
  bytes (shaded) per sample, read as one coalesced 32-byte transaction per warp thanks to the
  lane-interleaved tile layout, and one LUT lookup. Per candidate it is ~10–30× less memory
  traffic and ~10× fewer instructions than marching; the build (one march without TF, no
  skipping) is paid once per camera and is amortised after a few candidates, as on the CPU.
  It costs GPU memory: about (1 + 2 · shaded) bytes per sample, e.g. 115 M samples at 512²
  with the default step 0.5 through a 256³ volume: 0.12 GB unshaded, 0.35 GB shaded.
- **A single picture from a new camera (render, render_rgba, interactive views) marches
  directly**, with the TF's empty-space skipping and early termination: building a cache for
  one TF would sample every voxel along every ray, including those the TF makes empty.

Measured on an NVIDIA H200 (``benchmarks/gpu_check.sh``; figures, logs and agreement in
``benchmarks/gpu_results/``): a population of 50 on the 256³ foot at 0.16 ms per candidate
end to end at 256² shaded and 0.52 ms at 512², pictures within 1/255 of the CPU's. CI checks
the kernels under Numba's CUDA simulator (``tests/render/test_cuda_sim.py``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from intuitf.render import cuda_kernels as ck
from intuitf.render import kernels
from intuitf.render.cache import CacheViews, feature_shares, gaussian_params
from intuitf.render.camera import Camera, ViewFrame
from intuitf.render.context import RenderContext
from intuitf.render.renderer import BLOCK_SIZE, EARLY_STOP, VolumeRenderer
from intuitf.tf.gaussian import GaussianTF

#: numba.cuda, as cuda_kernels imported it (after making it importable: see cuda_compat).
cuda = ck.cuda

#: Bytes of pictures one launch may produce on the GPU (larger populations are split).
MAX_LAUNCH_OUTPUT = 1 << 30


class DeviceVolume:
    """A volume's data, and its shading voxels once asked for, in GPU memory (one per
    :class:`~intuitf.render.context.RenderContext`, so every renderer of the volume shares it)."""

    def __init__(self, context: RenderContext) -> None:
        self.context = context
        self.data = cuda.to_device(context.data)
        self.lit = None

    def shading_voxels(self) -> Any:
        """Int16 (z, y, x, 4) gradient and value code of each voxel, as the CPU's
        (:meth:`RenderContext.shading_voxels`): shaded samples read their value from the codes
        on both, so both round it to the same LUT entry."""
        if self.lit is None:
            ctx = self.context
            if ctx.has_gradient:
                lit = ctx.shading_voxels()
            else:  # computed here without keeping the 8-bytes-per-voxel host copy
                lit = np.empty(ctx.shape + (4,), dtype=np.int16)
                kernels.central_gradient(ctx.data, lit)
                kernels.value_codes(ctx.data, lit)
            self.lit = cuda.to_device(lit)
        return self.lit


class CudaBackend:
    """One renderer's GPU state: picture geometry, shading constants, launches."""

    def __init__(self, renderer: VolumeRenderer) -> None:
        self.renderer = renderer
        self.volume = renderer.context.gpu_volume()
        w, h = renderer.width, renderer.height
        self.tiles_x = -(-w // ck.TILE_W)
        self.n_tiles = self.tiles_x * -(-h // ck.TILE_H)
        self.n_slots = self.n_tiles * ck.WARP
        self.n_blocks = -(-self.n_slots // ck.BLOCK)
        self.isp = cuda.to_device((1.0 / renderer._spacing).astype(np.float32))
        self.shade = cuda.to_device(renderer.shade_params.astype(np.float32))
        self.bg = cuda.to_device(renderer.background.astype(np.float32))
        self.dt = np.float32(renderer.sample_distance)
        self.t_stop = np.float32(EARLY_STOP)
        self._no_lit = cuda.to_device(np.zeros((1, 1, 1, 4), dtype=np.int16))
        self._no_rgba = cuda.device_array((1, 1, 4), dtype=np.float32)
        self._no_rgb = cuda.device_array((1, 1, 3), dtype=np.uint8)

    # -- pieces ---------------------------------------------------------------------------
    def lit(self) -> Any:
        """The shading voxels when shading, else a stand-in the kernels never read."""
        return self.volume.shading_voxels() if self.renderer.shading else self._no_lit

    def cam(self, frame: ViewFrame) -> Any:
        return cuda.to_device(frame.packed().astype(np.float32))

    def classify(self, tfs: Sequence[GaussianTF]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The TFs' (:meth:`VolumeRenderer.classification`) stacked: (K, L, 4) float32
        straight-RGBA LUTs, (K, P, P, 4) premultiplied pre-integrated tables (stand-ins
        without pre-integration) and (K, L + 1) int32 occupancy."""
        cls = [self.renderer.classification(tf) for tf in tfs]
        return (
            np.stack([c.lut for c in cls]),
            np.stack([c.table for c in cls]),
            np.stack([c.occupied for c in cls]).astype(np.int32),
        )

    def _chunks(self, k: int, to8: bool) -> list[slice]:
        per = self.renderer.width * self.renderer.height * (3 if to8 else 16)
        step = max(1, min(k, MAX_LAUNCH_OUTPUT // per))
        return [slice(a, min(a + step, k)) for a in range(0, k, step)]

    def _outputs(self, k: int, to8: bool) -> tuple[Any, Any]:
        p = self.renderer.width * self.renderer.height
        if to8:
            return self._no_rgba, cuda.device_array((k, p, 3), dtype=np.uint8)
        return cuda.device_array((k, p, 4), dtype=np.float32), self._no_rgb

    def _pictures(self, out_rgba: Any, out_rgb: Any, to8: bool) -> np.ndarray:
        h, w = self.renderer.height, self.renderer.width
        if to8:
            return out_rgb.copy_to_host().reshape(-1, h, w, 3)
        return out_rgba.copy_to_host().reshape(-1, h, w, 4)

    # -- direct marching ------------------------------------------------------------------
    def march(
        self,
        tfs: Sequence[GaussianTF],
        frame: ViewFrame,
        *,
        nearest: bool = False,
        to8: bool = True,
    ) -> np.ndarray:
        """Ray-march K TFs: (K, H, W, 3) uint8 over the background, or (K, H, W, 4) RGBA."""
        r = self.renderer
        lo, hi = r._block_ranges()
        cam = self.cam(frame)
        lit = self.lit()
        luts, tables, occs = self.classify(tfs)
        parts = []
        for part in self._chunks(luts.shape[0], to8):
            lut = np.ascontiguousarray(luts[part])
            occ = occs[part]
            vis = np.ascontiguousarray((occ[:, hi + 1] > occ[:, lo]).astype(np.uint8))
            k = lut.shape[0]
            out_rgba, out_rgb = self._outputs(k, to8)
            ck.march[k * self.n_blocks, ck.BLOCK](
                self.volume.data, lit, r.shading, cuda.to_device(vis), BLOCK_SIZE,
                cuda.to_device(lut), cuda.to_device(np.ascontiguousarray(tables[part])),
                r.preintegrated, bool(nearest), cam, self.isp, self.dt, self.shade,
                self.t_stop, self.tiles_x, self.bg, to8, out_rgba, out_rgb,
            )  # fmt: skip
            parts.append(self._pictures(out_rgba, out_rgb, to8))
        return parts[0] if len(parts) == 1 else np.concatenate(parts)


class CudaSampleCache(CacheViews):
    """:class:`SampleCache` on the GPU: one camera's samples, rendered for many TFs.

    Same samples, same rounding (value to the nearest LUT entry, shading terms to 1/255) as
    the CPU cache, stored in GPU memory in the lane-interleaved tile layout described in
    :mod:`.cuda_kernels`. :meth:`render_many` renders a population in one launch.
    """

    def __init__(
        self, renderer: VolumeRenderer, camera: Camera, frame: ViewFrame, backend: CudaBackend,
        counts: Any, tile_base: Any, samples: Any, diffuse: Any, specular: Any, segmin: Any,
        segmax: Any, n_samples: int,
    ) -> None:  # fmt: skip
        self.renderer = renderer
        self.camera = camera
        self.frame = frame
        self.backend = backend
        self.counts = counts
        self.tile_base = tile_base
        self.samples = samples
        self.diffuse = diffuse
        self.specular = specular
        self.segmin = segmin
        self.segmax = segmax
        self._n_samples = n_samples

    @classmethod
    def build(cls, renderer: VolumeRenderer, camera: Camera) -> CudaSampleCache:
        """Sample ``renderer``'s volume along every ray of ``camera``, on the GPU."""
        be = renderer._cuda_backend()
        frame = renderer.frame(camera)
        # The build follows the CPU's float64 ray positions and interpolation: a value is
        # rounded to its LUT entry here, and float32 would land a few values per thousand on
        # the neighbouring entry (a visible step where a narrow Gaussian is steep).
        cam = cuda.to_device(frame.packed().astype(np.float64))
        isp = cuda.to_device((1.0 / renderer._spacing).astype(np.float64))
        dt = np.float64(renderer.sample_distance)
        nz, ny, nx = renderer.volume.data.shape
        counts = cuda.device_array(be.n_slots, dtype=np.int32)
        t0s = cuda.device_array(be.n_slots, dtype=np.float64)
        blocks = be.n_blocks
        ck.count_samples[blocks, ck.BLOCK](cam, isp, nx, ny, nz, dt, be.tiles_x, counts, t0s)
        host_counts = counts.copy_to_host()
        longest = host_counts.reshape(be.n_tiles, ck.WARP).max(axis=1).astype(np.int64)
        tile_len = -(-longest // ck.SEG) * ck.SEG
        tile_base = np.zeros(be.n_tiles + 1, dtype=np.int64)
        np.cumsum(tile_len * ck.WARP, out=tile_base[1:])
        stored = int(tile_base[-1])
        nl = renderer.lut_size
        dtype = np.uint8 if nl <= 256 else np.uint16
        samples = cuda.device_array(max(stored, 1), dtype=dtype)
        segmin = cuda.device_array(max(stored // ck.SEG, 1), dtype=dtype)
        segmax = cuda.device_array(max(stored // ck.SEG, 1), dtype=dtype)
        if renderer.shading:
            diffuse = cuda.device_array(max(stored, 1), dtype=np.uint8)
            specular = cuda.device_array(max(stored, 1), dtype=np.uint8)
        else:
            diffuse = specular = cuda.device_array(1, dtype=np.uint8)
        d_base = cuda.to_device(tile_base)
        ck.fill_samples[blocks, ck.BLOCK](
            be.volume.data, be.lit(), renderer.shading, cam, isp, dt, nl,
            np.float64(renderer.shade_params[3]), be.tiles_x, counts, t0s, d_base, samples,
            diffuse, specular, segmin, segmax,
        )  # fmt: skip
        return cls(
            renderer, camera, frame, be, counts, d_base, samples, diffuse, specular, segmin,
            segmax, int(host_counts.sum()),
        )  # fmt: skip

    # -- facts ----------------------------------------------------------------------------
    @property
    def n_samples(self) -> int:
        """Samples on the rays (not counting the padding of the tiled layout)."""
        return self._n_samples

    @property
    def nbytes(self) -> int:
        """GPU memory held by the cache's arrays."""
        arrays = (
            self.counts, self.tile_base, self.samples, self.diffuse, self.specular, self.segmin,
            self.segmax,
        )  # fmt: skip
        return int(sum(a.size * a.dtype.itemsize for a in arrays))

    # -- rendering ------------------------------------------------------------------------
    def upload(self, tfs: Sequence[GaussianTF], to8: bool = True) -> list[tuple]:
        """The TFs' LUTs, pre-integrated tables and occupancy on the GPU, in launch-sized
        parts: (K, luts, tables, occ)."""
        be = self.backend
        luts, tables, occs = be.classify(tfs)
        if not self.renderer.shading:
            luts[:, :, :3] *= luts[:, :, 3:4]  # premultiplied, as composite_unshaded
        parts = []
        for part in be._chunks(luts.shape[0], to8):
            lut = np.ascontiguousarray(luts[part])
            parts.append((
                lut.shape[0], cuda.to_device(lut),
                cuda.to_device(np.ascontiguousarray(tables[part])),
                cuda.to_device(np.ascontiguousarray(occs[part])),
            ))  # fmt: skip
        return parts

    def launch(self, k: int, luts: Any, tables: Any, occ: Any, to8: bool = True) -> tuple[Any, Any]:
        """Composite K uploaded LUTs in one launch; returns the (RGBA, RGB) device outputs.

        Asynchronous: the benchmark times it with CUDA events; :meth:`render_many` uses it.
        """
        be = self.backend
        r = self.renderer
        out_rgba, out_rgb = be._outputs(k, to8)
        ck.composite[k * be.n_blocks, ck.BLOCK](
            self.counts, self.tile_base, self.samples, self.diffuse, self.specular, self.segmin,
            self.segmax, occ, luts, tables, r.preintegrated, r.shading, be.shade, be.t_stop,
            be.tiles_x, r.width, r.height, be.bg, to8, out_rgba, out_rgb,
        )  # fmt: skip
        return out_rgba, out_rgb

    def _composite(self, tfs: Sequence[GaussianTF], to8: bool) -> np.ndarray:
        pictures = [
            self.backend._pictures(*self.launch(k, luts, tables, occ, to8), to8)
            for k, luts, tables, occ in self.upload(tfs, to8)
        ]
        return pictures[0] if len(pictures) == 1 else np.concatenate(pictures)

    def render_rgba(self, tf: GaussianTF) -> np.ndarray:
        """Premultiplied RGBA float32 (H, W, 4) of ``tf``."""
        return self._composite([tf], to8=False)[0]

    def bytes_read(self, tfs: Sequence[GaussianTF]) -> np.ndarray:
        """Bytes of the cache that rendering each TF reads (with skipping and early stop).

        For bandwidth figures only: samples loaded times their bytes (1 for the value, 2 more
        for the shading terms), plus each checked segment's (min, max). (K,) int64.
        """
        be = self.backend
        r = self.renderer
        luts, _, occs = be.classify(tfs)
        alphas = np.ascontiguousarray(luts[:, :, 3])
        checked = np.zeros(len(alphas), dtype=np.int64)
        loaded = np.zeros(len(alphas), dtype=np.int64)
        for a in range(0, len(alphas), 8):
            alpha = alphas[a : a + 8]
            k = alpha.shape[0]
            reads = cuda.to_device(np.zeros((k, be.n_slots, 2), dtype=np.int32))
            ck.count_reads[k * be.n_blocks, ck.BLOCK](
                self.counts, self.tile_base, self.samples, self.segmin, self.segmax,
                cuda.to_device(np.ascontiguousarray(occs[a : a + 8])), cuda.to_device(alpha),
                be.t_stop,
                be.tiles_x, r.width, r.height, reads,
            )  # fmt: skip
            sums = reads.copy_to_host().sum(axis=1, dtype=np.int64)
            checked[a : a + k] = sums[:, 0]
            loaded[a : a + k] = sums[:, 1]
        item = self.samples.dtype.itemsize
        return (loaded * (item + (2 if r.shading else 0)) + checked * 2 * item).astype(np.int64)

    def render(self, tf: GaussianTF) -> np.ndarray:
        """RGB uint8 (H, W, 3) of ``tf`` over the renderer's background."""
        return self._composite([tf], to8=True)[0]

    def render_many(self, tfs: Sequence[GaussianTF]) -> list[np.ndarray]:
        """RGB uint8 (H, W, 3) of each TF, in order, rendered in one launch."""
        tfs = list(tfs)
        if not tfs:
            return []
        return list(self._composite(tfs, to8=True))

    def render_rgba_many(self, tfs: Sequence[GaussianTF]) -> np.ndarray:
        """Premultiplied RGBA float32 (K, H, W, 4) of each TF, in one launch."""
        return self._composite(list(tfs), to8=False)

    # -- feature attribution --------------------------------------------------------------
    def attribution(self, tf: GaussianTF) -> np.ndarray:
        """Each Gaussian's share of every pixel's opacity: float32 (N, H, W)."""
        be = self.backend
        r = self.renderer
        cls = r.classification(tf)
        lut = cls.lut
        out = cuda.to_device(np.zeros((len(tf), r.width * r.height), dtype=np.float32))
        ck.attribute[be.n_blocks, ck.BLOCK](
            self.counts, self.tile_base, self.samples, self.segmin, self.segmax,
            cuda.to_device(cls.occupied.astype(np.int32)),
            cuda.to_device(np.ascontiguousarray(lut[:, 3])),
            cuda.to_device(feature_shares(tf, lut.shape[0])),
            cuda.to_device(np.ascontiguousarray(cls.table[None])), r.preintegrated,
            cuda.to_device(gaussian_params(tf).astype(np.float32)), be.t_stop, be.tiles_x,
            r.width, r.height, out,
        )  # fmt: skip
        return out.copy_to_host().reshape(len(tf), r.height, r.width)
