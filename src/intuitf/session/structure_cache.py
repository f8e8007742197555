"""A volume's structure map kept on disk, so that opening the volume again does not rebuild it.

The structure map (:mod:`intuitf.intent.structures`) takes from a fraction of a second to a
few seconds to build, and a model judge pays a call to name its structures
(:mod:`intuitf.session.naming`). Both are kept in a per-user cache folder, one entry per
volume content and map version::

    $INTUITF_CACHE_DIR/structures/      (default: $XDG_CACHE_HOME/intuitf or ~/.cache/intuitf)
        <content hash>-v<version>.json   the map (StructureMap.to_dict(), names included)
        <content hash>-v<version>.npz    its label grid (reduced size), for atlas and views

The key is a hash of the volume's normalised values, shape and spacing, so the same data read
from another path, or by another front end, finds the same entry; a new map version (another
decomposition) simply misses. A damaged or unreadable entry is rebuilt, never an error, and a
cache that cannot be written is skipped (the map is still used from memory).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from intuitf.intent.structures import STRUCTURE_MAP_VERSION, StructureMap

log = logging.getLogger(__name__)

__all__ = ["cache_dir", "cached_structure_map", "content_hash", "remember_names", "store_map"]


def cache_dir() -> Path:
    """The folder structure maps are cached in (``$INTUITF_CACHE_DIR/structures``)."""
    root = os.environ.get("INTUITF_CACHE_DIR")
    if not root:
        xdg = os.environ.get("XDG_CACHE_HOME")
        root = str(Path(xdg) / "intuitf") if xdg else str(Path.home() / ".cache" / "intuitf")
    return Path(root).expanduser() / "structures"


def content_hash(volume: Any) -> str:
    """A hash of what the map is computed from: the normalised values, shape and spacing."""
    h = hashlib.blake2b(digest_size=16)
    data = np.ascontiguousarray(volume.data, dtype=np.float32)
    h.update(repr((data.shape, tuple(float(s) for s in volume.spacing))).encode())
    h.update(data.tobytes())
    return h.hexdigest()


def _paths(key: str) -> tuple[Path, Path]:
    stem = cache_dir() / f"{key}-v{STRUCTURE_MAP_VERSION}"
    return stem.with_suffix(".json"), stem.with_suffix(".npz")


def _key_of(volume: Any) -> str:
    # Hashing a large volume takes a moment: once per volume object.
    key = getattr(volume, "_structure_key", None)
    if key is None:
        key = content_hash(volume)
        try:
            volume._structure_key = key
        except AttributeError:  # a volume type that takes no new attributes
            pass
    return str(key)


def load_map(volume: Any) -> StructureMap | None:
    """The cached map of ``volume`` (None when there is none, or it cannot be read)."""
    js, npz = _paths(_key_of(volume))
    if not js.is_file():
        return None
    try:
        d = json.loads(js.read_text(encoding="utf-8"))
        smap = StructureMap.from_dict(d)
        smap.voxel_size = tuple(float(v) for v in d.get("voxel_size", (1.0, 1.0, 1.0)))  # type: ignore[assignment]
        if npz.is_file():
            with np.load(npz) as z:
                labels = z["labels"]
            if tuple(labels.shape) == tuple(smap.shape):
                smap.labels = labels
        return smap
    except (OSError, ValueError, KeyError, TypeError) as exc:
        log.info("The cached structure map %s is unreadable (%s); building it again.", js, exc)
        return None


def store_map(volume: Any, smap: StructureMap) -> None:
    """Write ``smap`` as ``volume``'s cached map (atomically; skipped when the cache is not
    writable)."""
    from intuitf.session.rundir import atomic_write_bytes

    js, npz = _paths(_key_of(volume))
    d = smap.to_dict()
    d["voxel_size"] = list(smap.voxel_size)
    d["version"] = STRUCTURE_MAP_VERSION
    try:
        js.parent.mkdir(parents=True, exist_ok=True)
        if smap.labels is not None:
            import io

            buf = io.BytesIO()
            np.savez_compressed(buf, labels=np.asarray(smap.labels))
            atomic_write_bytes(npz, buf.getvalue())
        atomic_write_bytes(js, json.dumps(d, indent=1).encode("utf-8"))
    except Exception as exc:  # noqa: BLE001 - a cache that cannot be written is only slower
        log.warning("Could not cache the structure map in %s: %s", js.parent, exc)


def cached_structure_map(volume: Any) -> StructureMap:
    """``volume``'s structure map: the one in memory, else the cached one, else built (and
    cached). The map is kept in memory with the volume
    (:func:`intuitf.intent.hints.remember_structure_map`), so words and views use it."""
    from intuitf.intent.hints import known_structure_map, remember_structure_map, structure_map_of

    smap = known_structure_map(volume)
    if smap is not None:
        return smap
    smap = load_map(volume)
    if smap is not None:
        remember_structure_map(volume, smap)
        return smap
    smap = structure_map_of(volume)
    store_map(volume, smap)
    return smap


def remember_names(volume: Any, names: dict[int, str]) -> StructureMap:
    """Name ``volume``'s structures (structure id -> name): kept in memory and in the cache."""
    from intuitf.intent.hints import remember_structure_map

    named = cached_structure_map(volume).named(names)
    remember_structure_map(volume, named)
    store_map(volume, named)
    return named
