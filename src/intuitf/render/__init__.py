"""Direct volume rendering of Gaussian-mixture transfer functions.

- :class:`Camera`: an orbit camera whose default view fits the volume's physical box.
- :class:`VolumeRenderer`: a Numba ray caster (trilinear, post-classification, front-to-back,
  early ray termination, empty-space skipping, Blinn–Phong headlight shading).
- :class:`SampleCache`: the volume sampled once per camera, so that each candidate TF of a
  generation costs only a LUT lookup and compositing per sample; it also splits each pixel's
  opacity among the TF's Gaussians (attribution, picking, single-feature views).

Devices
-------
``VolumeRenderer(volume, device="auto" | "cpu" | "cuda")``: the same interface runs on the CPU
(Numba, the reference) or on an NVIDIA GPU (``numba.cuda``, :mod:`.cuda_backend`; install
``intuitf[cuda]``). ``auto`` takes the GPU when one is usable and the CPU otherwise;
:func:`select_device` says which. On the GPU the volume and its gradient stay in GPU memory,
``renderer.sample_cache(camera)`` is a GPU sample cache, and ``cache.render_many(tfs)`` /
``renderer.render_many(tfs, camera)`` render a whole population in one launch (on the CPU they
loop: batching TFs does not pay there, since a ray can only stop when every TF lets it). CI
checks the CUDA kernels against the CPU kernels under Numba's CUDA simulator.
"""

from typing import TYPE_CHECKING

from intuitf._lazy import lazy_exports

if TYPE_CHECKING:  # the names below, for type checkers and editors
    from intuitf.render.cache import SampleCache
    from intuitf.render.camera import Camera, ViewFrame
    from intuitf.render.device import select_device
    from intuitf.render.renderer import VolumeRenderer

_EXPORTS = {
    "SampleCache": "intuitf.render.cache",
    "Camera": "intuitf.render.camera",
    "ViewFrame": "intuitf.render.camera",
    "VolumeRenderer": "intuitf.render.renderer",
    "select_device": "intuitf.render.device",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = ["Camera", "SampleCache", "ViewFrame", "VolumeRenderer", "select_device"]
