"""Direct volume rendering of Gaussian-mixture transfer functions.

- :class:`Camera`: an orbit camera whose default view fits the volume's physical box.
- :class:`VolumeRenderer`: a Numba ray caster (trilinear, post-classification, front-to-back,
  early ray termination, empty-space skipping, Blinn–Phong headlight shading).
- :class:`SampleCache`: the volume sampled once per camera, so that each candidate TF of a
  generation costs only a LUT lookup and compositing per sample; it also splits each pixel's
  opacity among the TF's Gaussians (attribution, picking, single-feature views).

Design note: a batched GPU backend (not built)
----------------------------------------------
A PyTorch/CUDA backend would sit behind the same two calls, ``renderer.sample_cache(camera)``
and ``cache.render(tf)`` / ``cache.render_rgba(tf)`` / ``cache.attribution(tf)``, plus a
``cache.render_many(tfs)`` that the CPU path implements as a loop:

- Build: one ``torch.nn.functional.grid_sample`` over the volume texture for all rays, dense
  (rays × longest ray), storing the LUT index (uint8/int16, with a sentinel row for samples
  outside the box) and the two shading terms. Index space and sample positions stay exactly
  those of :mod:`intuitf.render.kernels`, so CPU and GPU images agree within float rounding.
- Render a batch of K TFs: stack their corrected LUTs into a (L + 1, 4K) table whose last row
  is empty, gather with ``F.embedding``, composite with an exclusive ``cumprod`` of ``1 - a``
  and a weighted sum along the ray. Dense compositing has no early termination; where that
  matters a Triton/Numba-CUDA port of :func:`kernels.composite` keeps it.
- Selection: ``VolumeRenderer(volume, backend="auto" | "cpu" | "cuda")``; the CPU kernels stay
  the reference, and tests compare the two on small volumes. Batching TFs does not pay on
  the CPU (rays can only stop when every TF lets them), so the CPU path keeps one TF per pass.
"""

from typing import TYPE_CHECKING

from intuitf._lazy import lazy_exports

if TYPE_CHECKING:  # the names below, for type checkers and editors
    from intuitf.render.cache import SampleCache
    from intuitf.render.camera import Camera, ViewFrame
    from intuitf.render.renderer import VolumeRenderer

_EXPORTS = {
    "SampleCache": "intuitf.render.cache",
    "Camera": "intuitf.render.camera",
    "ViewFrame": "intuitf.render.camera",
    "VolumeRenderer": "intuitf.render.renderer",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = ["Camera", "SampleCache", "ViewFrame", "VolumeRenderer"]
