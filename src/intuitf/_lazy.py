"""Public names of a package that load on first use (PEP 562), so ``import intuitf`` is fast.

A package lists its exports as ``{name: "module"}``; the first ``intuitf.tf.GaussianTF``
imports ``intuitf.tf.gaussian`` and remembers the value. Heavy dependencies (Numba, openai,
SciPy, scikit-image) load only when something that needs them is used.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable


def lazy_exports(package: str, exports: dict[str, str]) -> tuple[Callable, Callable]:
    """``(__getattr__, __dir__)`` for ``package`` whose ``exports`` map names to modules."""

    def __getattr__(name: str):
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(exports))

    return __getattr__, __dir__
