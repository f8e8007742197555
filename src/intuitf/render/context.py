"""The render context of a volume: what rendering it needs, made once per process.

A volume's derived rendering data is large: the shading voxels (int16 central-difference
gradient and value, side by side) are 8 bytes a voxel (about 1.3 GB for a 512×512×614 CT, next
to 0.64 GB of float32 voxels), and the GPU copies of the data and gradient as much again in GPU
memory. Every renderer of a volume (the Session's, each interactive view size, drag frames, the
selection measures, ``RunStore.render``, batch's reference) takes it from one
:class:`RenderContext`, so it exists once whatever the number of renderers, views and front
ends.

``render_context(volume)`` returns the volume's context, made on first use and held by weak
reference to the volume: when the last reference to the volume goes, so does its context. The
context keeps no reference to the :class:`~intuitf.volume.Volume` object itself (that would keep
the volume alive forever), only to its voxel array.

The context also holds the volume's **device** (``"cpu"`` or ``"cuda"``): the first caller that
names one chooses it (until then it is ``"auto"``'s choice), and every renderer made without a
device of its own follows it. A Session makes its volume's context with its run's device, so the views,
picks and previews of that run render where the run does.
"""

from __future__ import annotations

import threading
import weakref
from typing import Any

import numpy as np

from intuitf.render import kernels
from intuitf.render.device import select_device
from intuitf.volume.volume import Volume

__all__ = ["BLOCK_SIZE", "FINE_BLOCK_SIZE", "RenderContext", "render_context"]

#: Block edge (cells) of the empty-space-skipping grid of the direct renderer: rays jump over
#: blocks that no sample of the TF can see.
BLOCK_SIZE = 8
#: Block edge (cells) of the direct renderer's fine grid: inside a visible block, a sample whose
#: fine block no value of the TF can see is passed over without interpolating or classifying.
FINE_BLOCK_SIZE = 2


class RenderContext:
    """One volume's gradient, empty-space block ranges, GPU copies and device choice.

    Each piece is built on first use, once, under a lock (two threads asking at the same time
    wait for one computation). Use :func:`render_context` rather than this constructor, so that
    the context is shared.
    """

    def __init__(self, volume: Volume, device: str = "auto") -> None:
        self.data: np.ndarray = volume.data
        nz, ny, nx = (int(n) for n in volume.data.shape)
        self.shape: tuple[int, int, int] = (nz, ny, nx)
        self.name = volume.name
        #: ``"cpu"`` or ``"cuda"``: where renderers of this volume run unless told otherwise.
        self.device: str = select_device(device)
        self._device_named = False
        self._lock = threading.Lock()
        self._lit: np.ndarray | None = None
        self._grad: np.ndarray | None = None
        self._blocks: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self._gpu: Any = None

    @property
    def has_gradient(self) -> bool:
        """Whether the host gradient has been computed."""
        return self._lit is not None

    def shading_voxels(self) -> np.ndarray:
        """Int16 (z, y, x, 4): the central-difference gradient (``kernels.central_gradient``)
        and the value's code (``kernels.value_codes``) of each voxel, computed on first use.

        What a shaded sample reads, together: its eight corners take half the cache lines
        that a separate value array and gradient take.
        """
        with self._lock:
            if self._lit is None:
                lit = np.empty(self.shape + (4,), dtype=np.int16)
                kernels.central_gradient(self.data, lit)
                kernels.value_codes(self.data, lit)
                self._lit = lit
                self._grad = lit[..., :3]
            return self._lit

    def gradient(self) -> np.ndarray:
        """Int16 central-difference gradient (z, y, x, 3): a view of :meth:`shading_voxels`."""
        self.shading_voxels()
        assert self._grad is not None
        return self._grad

    def block_ranges(self, lut_size: int, bsize: int = BLOCK_SIZE) -> tuple[np.ndarray, np.ndarray]:
        """LUT index range (lo, hi) that the samples of each block of ``bsize`` cells can take
        (uint16; per LUT size and block size)."""
        with self._lock:
            got = self._blocks.get((lut_size, bsize))
            if got is None:
                nz, ny, nx = self.shape
                shape = tuple(max(1, -(-(n - 1) // bsize)) for n in (nz, ny, nx))
                bmin = np.empty(shape, dtype=np.float32)
                bmax = np.empty(shape, dtype=np.float32)
                kernels.block_minmax(self.data, bsize, bmin, bmax)
                scale = lut_size - 1
                lo = np.clip(np.floor(bmin * scale), 0, scale).astype(np.uint16)
                hi = np.clip(np.ceil(bmax * scale), 0, scale).astype(np.uint16)
                got = self._blocks[(lut_size, bsize)] = (lo, hi)
            return got

    def gpu_volume(self) -> Any:
        """The volume's data (and, once asked for, its gradient) in GPU memory."""
        with self._lock:
            if self._gpu is None:
                from intuitf.render.cuda_backend import DeviceVolume

                self._gpu = DeviceVolume(self)
            return self._gpu

    def nbytes(self) -> int:
        """Host bytes this context holds beyond the voxels (gradient and block ranges)."""
        n = self._lit.nbytes if self._lit is not None else 0
        return n + sum(lo.nbytes + hi.nbytes for lo, hi in self._blocks.values())

    def __repr__(self) -> str:
        return f"RenderContext({self.name!r}, {self.shape}, device={self.device!r})"


_CONTEXTS: weakref.WeakKeyDictionary[Volume, RenderContext] = weakref.WeakKeyDictionary()
_CONTEXTS_LOCK = threading.Lock()


def render_context(volume: Volume, device: str | None = None) -> RenderContext:
    """The render context of ``volume``, made on first use (shared by weak reference).

    ``device`` (``"auto"``, ``"cpu"`` or ``"cuda"``) chooses the volume's device if no caller
    has named one yet; after that it is left as it is (a renderer that must run elsewhere names
    its own device). A device that cannot be used raises :class:`~intuitf.errors.RenderError`.
    """
    with _CONTEXTS_LOCK:
        ctx = _CONTEXTS.get(volume)
        if ctx is None:
            ctx = _CONTEXTS[volume] = RenderContext(volume, device or "auto")
            ctx._device_named = device is not None
        elif device is not None and not ctx._device_named:
            ctx.device = select_device(device)
            ctx._device_named = True
        return ctx
