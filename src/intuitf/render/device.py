"""Which device renders: the CPU (Numba, always there) or an NVIDIA GPU (``numba.cuda``).

``select_device("auto")`` picks the GPU when one is usable and the CPU otherwise, silently;
``select_device("cuda")`` insists on the GPU and raises a :class:`RenderError` saying why it
cannot be used. Nothing here needs a GPU, a CUDA toolkit or the ``intuitf[cuda]`` extra:
``numba.cuda`` is imported only to ask, and its failures become a one-line reason.

Under Numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``, set before ``numba.cuda`` is first
imported) ``"cuda"`` runs the GPU kernels in Python on the CPU, which the tests use to check
them without a GPU; ``"auto"`` never picks the simulator (it is thousands of times slower).
"""

from __future__ import annotations

import functools
import warnings

from intuitf.errors import RenderError

DEVICES = ("auto", "cpu", "cuda")


def _first_line(text: object) -> str:
    for line in str(text).splitlines():
        line = line.strip().rstrip(":.").strip()
        if line and not line.lower().startswith("error at driver init"):
            return line
    return ""


def simulator_enabled() -> bool:
    """True when Numba's CUDA simulator stands in for a GPU in this process."""
    try:
        from numba.core import config
    except ImportError:  # pragma: no cover - numba is a dependency
        return False
    return bool(getattr(config, "ENABLE_CUDASIM", 0))


@functools.lru_cache(maxsize=1)
def cuda_unavailable_reason() -> str | None:
    """Why the CUDA backend cannot run in this process, or None when it can."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from intuitf.render.cuda_compat import prepare_numba_cuda

            prepare_numba_cuda()  # numba-cuda with NumPy >= 2.5
            from numba import cuda
    except Exception as exc:  # numba without a CUDA target (built-in target removed)
        return f"numba.cuda cannot be imported ({_first_line(exc) or type(exc).__name__})"
    if simulator_enabled():
        return None
    try:
        if not cuda.is_available():
            err = cuda.cuda_error() if hasattr(cuda, "cuda_error") else None
            return _first_line(err) or "no CUDA driver or NVIDIA GPU was found"
        cuda.get_current_device()
    except Exception as exc:
        return _first_line(exc) or type(exc).__name__
    try:  # the kernel compiler (from a CUDA toolkit, or the nvidia wheels of intuitf[cuda])
        from numba.cuda.cudadrv import nvvm

        if hasattr(nvvm, "is_available") and not nvvm.is_available():
            return "the CUDA compiler library (NVVM) was not found"
    except ImportError:
        pass
    return None


def select_device(device: str = "auto") -> str:
    """``"cpu"`` or ``"cuda"``: the device that renders for the request ``auto|cpu|cuda``."""
    name = str(device).strip().lower()
    if name not in DEVICES:
        raise RenderError(f"Unknown render device {device!r}.", f"Use one of {', '.join(DEVICES)}.")
    if name == "cpu":
        return "cpu"
    if name == "auto":
        if simulator_enabled():
            return "cpu"
        return "cuda" if cuda_unavailable_reason() is None else "cpu"
    reason = cuda_unavailable_reason()
    if reason is not None:
        raise RenderError(
            f"The CUDA device was asked for, but no NVIDIA GPU can be used here: {reason}.",
            "Use --device cpu (or auto, which falls back to the CPU); on a machine with an "
            "NVIDIA GPU and driver, install the GPU support: pip install 'intuitf[cuda]'.",
        )
    return "cuda"
