"""Volumes: the :class:`Volume` type, readers for common formats, and a procedural phantom."""

from intuitf.volume.load import load_volume
from intuitf.volume.phantom import phantom
from intuitf.volume.volume import Volume

__all__ = ["Volume", "load_volume", "phantom"]
