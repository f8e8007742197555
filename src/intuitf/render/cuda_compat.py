"""Make ``numba.cuda`` importable with the NumPy it is installed next to.

numba-cuda (every release up to at least 0.30.4) registers a CUDA implementation of
``np.row_stack`` at import time whenever NumPy is 2.x; NumPy 2.5 removed ``row_stack``
(deprecated in 2.0 as an alias of ``vstack``), so on such a machine ``from numba import cuda``
fails with ``AttributeError: module 'numpy' has no attribute 'row_stack'`` before any kernel is
compiled. This was seen with the CUDA 13 numba-cuda next to NumPy 2.5 on an H200 machine.

:func:`prepare_numba_cuda` puts back ``numpy.row_stack`` as ``numpy.vstack`` (what it was an
alias of) only when NumPy lacks it, and must run before ``numba.cuda`` is first imported in the
process; every module of intuitf that imports ``numba.cuda`` calls it first. With NumPy < 2.5
(e.g. the ``cuda`` extra's CUDA 12 install with NumPy 2.4) it changes nothing.
"""

from __future__ import annotations

import numpy as np

#: NumPy attributes numba-cuda looks up at import time, and what each was an alias of.
_REMOVED_ALIASES = {"row_stack": "vstack"}


def prepare_numba_cuda() -> list[str]:
    """Restore the NumPy aliases numba-cuda needs at import; returns the names restored."""
    restored = []
    for name, target in _REMOVED_ALIASES.items():
        if not hasattr(np, name):
            setattr(np, name, getattr(np, target))
            restored.append(name)
    return restored
