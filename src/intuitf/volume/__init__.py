"""Volumes: the :class:`Volume` type, readers for common formats, and a procedural phantom."""

from typing import TYPE_CHECKING

from intuitf._lazy import lazy_exports

if TYPE_CHECKING:  # the names below, for type checkers and editors
    from intuitf.volume.load import load_volume
    from intuitf.volume.phantom import phantom
    from intuitf.volume.volume import Volume

_EXPORTS = {
    "load_volume": "intuitf.volume.load",
    "phantom": "intuitf.volume.phantom",
    "Volume": "intuitf.volume.volume",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

# ``phantom`` is both a submodule and a function: importing the submodule (as anything that
# uses it does) would bind the module to the package's name, so the function is bound here.
from intuitf.volume.phantom import phantom  # noqa: E402

__all__ = ["Volume", "load_volume", "phantom"]
