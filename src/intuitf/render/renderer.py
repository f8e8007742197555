"""The :class:`VolumeRenderer`: a Numba ray caster for Gaussian-mixture transfer functions."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from intuitf.errors import RenderError
from intuitf.render import kernels
from intuitf.render.camera import Camera, ViewFrame
from intuitf.render.context import BLOCK_SIZE, FINE_BLOCK_SIZE, RenderContext, render_context
from intuitf.render.device import select_device
from intuitf.tf.gaussian import GaussianTF
from intuitf.tf.preintegration import TABLE_SIZE, preintegrated_table
from intuitf.volume.volume import Volume

if TYPE_CHECKING:
    from intuitf.render.cache import CacheViews
    from intuitf.render.cuda_backend import CudaBackend

#: LUT alphas below this are treated as empty, so Gaussian tails (1e-30 ...) do not defeat
#: empty-space skipping. 300 such samples would block under 0.3 % of the light (< 1/255).
ALPHA_EPSILON = 1e-5
#: Rays stop once their transmittance drops below this: what is lost stays under 1/255.
EARLY_STOP = 1.0 / 255.0
MAX_IMAGE_SIDE = 4096
#: A single picture (``render``: views, drag frames, previews) up to this many pixels is
#: composited over the background with NumPy: the same bytes as the parallel kernel, without a
#: kernel launch that on a busy machine waits for an OpenMP thread to be scheduled (about 10 ms
#: a frame under load, for little work). A generation's pictures keep the kernel.
NUMPY_COMPOSITE_PIXELS = 512 * 512

__all__ = ["BLOCK_SIZE", "Classification", "VolumeRenderer"]

#: What kernels get for the table when a renderer does not pre-integrate (never read).
_NO_TABLE = np.zeros((2, 2, 4), dtype=np.float32)


@dataclass(frozen=True)
class Classification:
    """How a renderer's kernels classify samples for one TF.

    ``lut`` (L, 4) is the straight-RGBA LUT corrected for the sample distance; ``table``
    (P, P, 4) the premultiplied pre-integrated table (:mod:`intuitf.tf.preintegration`), a
    stand-in when the renderer does not pre-integrate; ``occupied`` (L + 1) counts the LUT
    entries below each index where a sample can show (with pre-integration, within one table
    entry of a visible one), so that a value range ``[lo, hi]`` can show nothing when
    ``occupied[hi + 1] == occupied[lo]``: what empty-space skipping asks.
    """

    lut: np.ndarray
    table: np.ndarray
    occupied: np.ndarray


def _parse_size(size: int | Sequence[int]) -> tuple[int, int]:
    if isinstance(size, int | np.integer):
        w = h = int(size)
    else:
        try:
            w, h = (int(v) for v in size)
        except (TypeError, ValueError) as exc:
            raise RenderError(f"Image size must be N or (width, height), got {size!r}.") from exc
    if not (1 <= w <= MAX_IMAGE_SIDE and 1 <= h <= MAX_IMAGE_SIDE):
        raise RenderError(
            f"Image size must be within 1–{MAX_IMAGE_SIDE} pixels per side, got {w}×{h}."
        )
    return w, h


def _parse_background(bg: Sequence[float]) -> np.ndarray:
    b = np.asarray(bg, dtype=np.float64).ravel()
    if b.size != 3 or not np.all(np.isfinite(b)) or b.min() < 0 or b.max() > 1:
        raise RenderError(
            f"Background must be three values in [0, 1], got {bg!r}.",
            "Use for example (0, 0, 0) for black or (1, 1, 1) for white.",
        )
    return b


class VolumeRenderer:
    """Renders one volume with any Gaussian TF and camera.

    ``size`` is N (square) or (width, height). ``sample_distance`` is the step along each ray in
    voxels (of the smallest spacing); opacity is corrected for it, one voxel being the unit
    length of :attr:`Gaussian.height`, so pictures do not change with the sampling rate.
    Shading is Blinn–Phong with a two-sided headlight: ``ambient``, ``diffuse``, ``specular``
    and ``shininess`` set it, ``shading=False`` turns it off. ``background`` is RGB in [0, 1].

    :meth:`render` ray-marches every sample (trilinear interpolation, front-to-back
    compositing, early ray termination, empty-space skipping over 8³ blocks, and inside
    visible ones samples passed over in 2³ blocks the TF cannot see). Each sample is classified
    with the segment from the previous one, from a pre-integrated table
    (:mod:`intuitf.tf.preintegration`): a Gaussian thinner than the values' step between two
    samples shows as the even shell it is, not as rings. ``preintegrated=False`` classifies
    each sample by its own value alone (post-classification with linear LUT interpolation,
    as VTK does). :meth:`sample_cache` samples the volume once for a camera so that
    many TFs can be rendered cheaply (see :class:`SampleCache`); :meth:`render_many` renders a
    whole population through one.

    ``device`` is ``"auto"`` (an NVIDIA GPU when one is usable, else the CPU), ``"cpu"`` or
    ``"cuda"`` (the GPU or a :class:`RenderError` saying why not); :attr:`device` is the one
    chosen. Both give the same pictures (see :mod:`intuitf.render.cuda_backend`). Left out
    (None), the renderer runs on its volume's device (:attr:`context`'s).

    What rendering the volume needs once (the gradient, the empty-space block ranges, the GPU
    copies) lives in the volume's :class:`~intuitf.render.context.RenderContext`, shared by
    every renderer of that volume; a renderer itself holds only its picture settings, so making
    one per picture size or view costs nothing.
    """

    def __init__(
        self,
        volume: Volume,
        *,
        size: int | Sequence[int] = 256,
        shading: bool = True,
        background: Sequence[float] = (0.0, 0.0, 0.0),
        sample_distance: float = 0.5,
        preintegrated: bool = True,
        ambient: float = 0.3,
        diffuse: float = 0.7,
        specular: float = 0.25,
        shininess: float = 24.0,
        device: str | None = None,
    ) -> None:
        if min(volume.dims) < 2:
            raise RenderError(
                f"{volume.name}: cannot ray-cast a volume with fewer than 2 voxels along an "
                f"axis (dims {volume.dims}).",
            )
        sd = float(sample_distance)
        if not (math.isfinite(sd) and 0.05 <= sd <= 4.0):
            raise RenderError(
                f"sample_distance must be within [0.05, 4] voxels, got {sample_distance!r}."
            )
        params = (ambient, diffuse, specular, shininess)
        if not all(math.isfinite(float(v)) and float(v) >= 0 for v in params):
            raise RenderError(f"Shading parameters must be non-negative, got {params!r}.")
        self.volume = volume
        self.width, self.height = _parse_size(size)
        self.shading = bool(shading)
        self.background = _parse_background(background)
        self.sample_distance = sd
        #: Whether samples are classified by the segment from the previous one
        #: (:mod:`intuitf.tf.preintegration`) instead of their own value alone.
        self.preintegrated = bool(preintegrated)
        self.shade_params = np.array([ambient, diffuse, specular, shininess], dtype=np.float64)
        # Geometry is measured in units of the smallest spacing (one voxel), so the opacity
        # unit length is 1 and the world step equals sample_distance.
        sp = np.asarray(volume.spacing, dtype=np.float64)
        self._spacing = sp / sp.min()
        self._extent = tuple((np.asarray(volume.dims) - 1) * self._spacing)
        #: The volume's shared rendering data (gradient, block ranges, device choice).
        self.context: RenderContext = render_context(volume)
        #: ``"cpu"`` or ``"cuda"``: where this renderer's kernels run.
        self.device = select_device(device) if device is not None else self.context.device
        self._cuda: CudaBackend | None = None

    # -- shared pieces --------------------------------------------------------------------
    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the pictures."""
        return self.width, self.height

    @property
    def lut_size(self) -> int:
        return self.volume.lut_size

    def frame(self, camera: Camera | None = None) -> ViewFrame:
        """The camera resolved for this volume (geometry in units of the smallest spacing)."""
        return (camera or Camera()).frame(self._extent, self.width, self.height)

    def lut(self, tf: GaussianTF) -> np.ndarray:
        """The TF's (L, 4) straight-RGBA table corrected for the sample distance."""
        if not isinstance(tf, GaussianTF):
            raise RenderError(f"Expected a GaussianTF, got {type(tf).__name__}.")
        table = tf.lut(self.lut_size, self.sample_distance)
        table[table[:, 3] < ALPHA_EPSILON, 3] = 0.0
        return np.ascontiguousarray(table, dtype=np.float32)

    def classification(self, tf: GaussianTF) -> Classification:
        """Everything the kernels classify samples with for ``tf`` (:class:`Classification`)."""
        lut = self.lut(tf)
        shows = lut[:, 3] > 0
        if self.preintegrated:
            table = preintegrated_table(
                tf, self.sample_distance, TABLE_SIZE, ALPHA_EPSILON, premultiply=True
            )
            # A segment's table entry can show the TF up to one table entry beyond its two
            # values (rounded, or interpolated, onto the table's grid): a value range counts
            # as visible when the TF shows within that reach of it.
            reach = -(-(lut.shape[0] - 1) // (TABLE_SIZE - 1))
            shows = np.convolve(shows, np.ones(2 * reach + 1), mode="same") > 0
        else:
            table = _NO_TABLE
        occupied = np.concatenate(([0], np.cumsum(shows))).astype(np.int64)
        return Classification(lut, np.ascontiguousarray(table, np.float32), occupied)

    def gradient(self) -> np.ndarray:
        """Int16 central-difference gradient (z, y, x, 3) of the volume (its context's)."""
        return self.context.gradient()

    def _shading_voxels(self) -> np.ndarray:
        """What the kernels read shaded samples from (a stand-in when not shading)."""
        if self.shading:
            return self.context.shading_voxels()
        return np.zeros((1, 1, 1, 4), dtype=np.int16)

    def _block_ranges(self) -> tuple[np.ndarray, np.ndarray]:
        """LUT index range (lo, hi) each empty-space block's samples can take."""
        return self.context.block_ranges(self.lut_size)

    def _visible_blocks(self, occupied: np.ndarray, bsize: int) -> np.ndarray:
        """uint8 per block of ``bsize`` cells: 1 where a sample can show (``occupied``:
        :attr:`Classification.occupied`)."""
        lo, hi = self.context.block_ranges(self.lut_size, bsize)
        vis = np.empty(lo.shape, dtype=np.uint8)
        kernels.visible_blocks(lo.ravel(), hi.ravel(), occupied, vis.reshape(-1))
        return vis

    def _cuda_backend(self) -> CudaBackend:
        """The GPU state (device arrays, launch geometry), made on first use."""
        if self._cuda is None:
            from intuitf.render.cuda_backend import CudaBackend

            self._cuda = CudaBackend(self)
        return self._cuda

    def to_rgb8(self, rgba: np.ndarray) -> np.ndarray:
        """Composite premultiplied RGBA (H, W, 4) over the background: uint8 (H, W, 3).

        The parallel kernel: the fastest on a machine with a core to spare (a generation's
        pictures, from the sample cache, come this way).
        """
        h, w = rgba.shape[:2]
        out = np.empty((h * w, 3), dtype=np.uint8)
        kernels.to_rgb8(np.ascontiguousarray(rgba.reshape(h * w, 4)), self.background, out)
        return out.reshape(h, w, 3)

    def to_rgb8_single(self, rgba: np.ndarray) -> np.ndarray:
        """:meth:`to_rgb8` for one interactive picture: up to NUMPY_COMPOSITE_PIXELS pixels
        with NumPy, in the kernel's arithmetic (float64, +0.5, clamp, truncate: the same
        bytes), without a parallel launch that waits for a thread on a busy machine."""
        h, w = rgba.shape[:2]
        if h * w > NUMPY_COMPOSITE_PIXELS:
            return self.to_rgb8(rgba)
        a = rgba.astype(np.float64, copy=False)
        v = (a[..., :3] + (1.0 - a[..., 3:4]) * self.background) * 255.0 + 0.5
        return np.clip(v, 0.0, 255.0).astype(np.uint8)

    # -- direct rendering -----------------------------------------------------------------
    def render_rgba(
        self, tf: GaussianTF, camera: Camera | None = None, *, nearest: bool = False
    ) -> np.ndarray:
        """Premultiplied RGBA float32 (H, W, 4) of ``tf`` seen from ``camera``.

        ``nearest=True`` classifies each sample by its nearest LUT entry instead of
        interpolating between entries: the sample cache's rule, for checking it.
        """
        if self.device == "cuda":
            frame = self.frame(camera)
            return self._cuda_backend().march([tf], frame, nearest=nearest, to8=False)[0]
        cls = self.classification(tf)
        frame = self.frame(camera)
        out = np.empty((self.width * self.height, 4), dtype=np.float32)
        kernels.march(
            self.volume.data,
            self._shading_voxels(),
            self.shading,
            self._visible_blocks(cls.occupied, BLOCK_SIZE),
            BLOCK_SIZE,
            self._visible_blocks(cls.occupied, FINE_BLOCK_SIZE),
            int(FINE_BLOCK_SIZE).bit_length() - 1,
            cls.lut,
            cls.table,
            self.preintegrated,
            bool(nearest),
            frame.packed(),
            self._spacing,
            self.sample_distance,
            self.shade_params,
            EARLY_STOP,
            out,
        )
        return out.reshape(self.height, self.width, 4)

    def render(self, tf: GaussianTF, camera: Camera | None = None) -> np.ndarray:
        """RGB uint8 (H, W, 3) of ``tf`` from ``camera``, composited over the background."""
        if self.device == "cuda":
            return self._cuda_backend().march([tf], self.frame(camera))[0]
        return self.to_rgb8_single(self.render_rgba(tf, camera))

    def sample_cache(self, camera: Camera | None = None) -> CacheViews:
        """Sample the volume once along every ray of ``camera``: a :class:`SampleCache`
        (a ``CudaSampleCache`` in GPU memory when :attr:`device` is ``"cuda"``)."""
        if self.device == "cuda":
            from intuitf.render.cuda_backend import CudaSampleCache

            return CudaSampleCache.build(self, camera or Camera())
        from intuitf.render.cache import SampleCache

        return SampleCache.build(self, camera or Camera())

    def render_many(
        self, tfs: Sequence[GaussianTF], camera: Camera | None = None
    ) -> list[np.ndarray]:
        """RGB uint8 (H, W, 3) of each TF from ``camera``: a population in one call.

        Samples the volume once for the camera and renders every TF from that (on the GPU in
        one launch). To render more TFs from the same camera later, keep
        ``cache = renderer.sample_cache(camera)`` and call ``cache.render_many(tfs)``.
        """
        tfs = list(tfs)
        if not tfs:
            return []
        return self.sample_cache(camera).render_many(tfs)
