"""The volumes an agent opens: found under the data roots, read with the project's readers,
named by a short id, each with a current transfer function the picture and TF tools act on.

A volume is described by a :class:`~intuitf.session.spec.VolumeSpec` (path and reader
options), exactly what a run records, so a run started on an open volume reads the same data.
Loaded arrays are kept for a few volumes at a time (least recently used dropped first) and read
again when needed; ids, specs and current TFs stay for the server's life.
"""

from __future__ import annotations

import os
import re
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from intuitf.errors import IntuitfError, SessionError
from intuitf.mcp.roots import PathRefused, Roots
from intuitf.session.spec import VolumeSpec
from intuitf.tf import GaussianTF

PHANTOM = "builtin:phantom"

#: File-name endings of the volume formats intuitf reads (a folder of DICOM slices aside).
VOLUME_SUFFIXES = (
    ".raw.gz", ".raw", ".dat", ".bin", ".vol", ".nrrd", ".nhdr", ".nii.gz", ".nii", ".mha",
    ".mhd", ".vti", ".tif", ".tiff", ".npy", ".npz", ".cvol",
)  # fmt: skip
_SHAPE_IN_NAME = re.compile(r"_(\d+)x(\d+)x(\d+)_([a-z]+\d*)", re.I)
#: How many volumes stay loaded at once.
KEEP_LOADED = 3
#: How deep and how many files :meth:`VolumeShelf.files` looks.
SCAN_DEPTH = 4
SCAN_LIMIT = 500


def _stem(name: str) -> str:
    low = name.lower()
    for s in VOLUME_SUFFIXES:
        if low.endswith(s):
            name = name[: -len(s)]
            break
    m = _SHAPE_IN_NAME.search(name)
    name = name[: m.start()] if m else name
    # The lossy copies of the shared data sets say so in their names; the id need not.
    return re.sub(r"_zfp\d+lossy$", "", name)


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")[:40] or "volume"


@dataclass
class OpenVolume:
    """A volume an agent opened: its id, where it comes from, and its current TF."""

    id: str
    spec: VolumeSpec
    tf: GaussianTF | None = None
    views: dict[tuple, Any] = field(default_factory=dict)

    def key(self) -> str:
        return _spec_key(self.spec)


def _spec_key(spec: VolumeSpec) -> str:
    import json

    return json.dumps([spec.source, spec.reader_options()], sort_keys=True, default=str)


class VolumeShelf:
    """Open volumes by id (thread-safe; loading blocks, so call it from a worker thread)."""

    def __init__(self, roots: Roots, *, max_dim: int | None = None, device: str = "auto") -> None:
        self.roots = roots
        self.max_dim = max_dim
        self.device = device
        self._lock = threading.RLock()
        self._open: dict[str, OpenVolume] = {}
        self._loaded: OrderedDict[str, Any] = OrderedDict()
        self._load_locks: dict[str, threading.Lock] = {}

    # -- what there is --------------------------------------------------------------------
    def files(self, limit: int = SCAN_LIMIT) -> list[dict[str, Any]]:
        """Volume files under the data roots (not following links out of them)."""
        out: list[dict[str, Any]] = []
        opened = {ov.spec.source: ov.id for ov in self._open.values()}
        for root in self.roots.data:
            if not root.is_dir():
                continue
            for folder, dirs, names in os.walk(root):
                depth = len(Path(folder).relative_to(root).parts)
                dirs[:] = (
                    sorted(d for d in dirs if not d.startswith(".")) if depth < SCAN_DEPTH else []
                )
                for n in sorted(names):
                    if n.startswith(".") or not n.lower().endswith(VOLUME_SUFFIXES):
                        continue
                    p = Path(folder) / n
                    try:
                        real = self.roots.readable(p, "volume file")
                    except PathRefused:
                        continue  # a link pointing out of the roots
                    m = _SHAPE_IN_NAME.search(n)
                    out.append(
                        {
                            "path": str(p),
                            "name": _stem(n),
                            "shape_xyz": [int(m.group(i)) for i in (1, 2, 3)] if m else None,
                            "dtype": m.group(4).lower() if m else None,
                            "bytes": real.stat().st_size,
                            "open_as": opened.get(str(real)),
                        }
                    )
                    if len(out) >= limit:
                        return out
        return out

    # -- opening --------------------------------------------------------------------------
    def open(self, path: str, **options: Any) -> OpenVolume:
        """Open the volume at ``path`` (under a data root) or ``phantom``, with reader options."""
        if path in ("phantom", PHANTOM):
            source = PHANTOM
        else:
            source = str(self.roots.readable(path, "volume file"))
        opts = {k: v for k, v in options.items() if v is not None}
        if self.max_dim and "max_dim" not in opts:
            opts["max_dim"] = self.max_dim
        try:
            spec = VolumeSpec(source=source, **opts)
        except ValueError as exc:
            raise SessionError(f"The reader options are not valid: {_first_error(exc)}.") from None
        ov = self.for_spec(spec)
        self.volume(ov)  # read it now: a file that does not load is reported here
        return ov

    def for_spec(self, spec: VolumeSpec) -> OpenVolume:
        """The open volume of ``spec`` (a run's volume), opened under a new id if need be.

        The source must lie under the data roots (or be the built-in phantom).
        """
        if spec.source not in ("phantom", PHANTOM):
            real = str(self.roots.readable(spec.source, "volume file"))
            if real != spec.source:
                spec = spec.model_copy(update={"source": real})
        key = _spec_key(spec)
        with self._lock:
            for ov in self._open.values():
                if ov.key() == key:
                    return ov
            base = (
                "phantom"
                if spec.source in ("phantom", PHANTOM)
                else _slug(_stem(Path(spec.source).name))
            )
            vid, k = base, 1
            while vid in self._open:
                k += 1
                vid = f"{base}-{k}"
            ov = OpenVolume(vid, spec)
            self._open[vid] = ov
            return ov

    def get(self, volume_id: Any) -> OpenVolume:
        ov = self._open.get(volume_id) if isinstance(volume_id, str) else None
        if ov is None:
            known = ", ".join(sorted(self._open)) or "none yet"
            raise SessionError(
                f"There is no open volume {str(volume_id)[:80]!r} (open: {known}).",
                "Open one with open_volume (its path from list_volumes) and use the id it returns.",
            )
        return ov

    def opened(self) -> list[OpenVolume]:
        with self._lock:
            return list(self._open.values())

    def volume(self, ov: OpenVolume):
        """The loaded :class:`~intuitf.volume.Volume` (blocking)."""
        key = ov.key()
        with self._lock:
            vol = self._loaded.get(key)
            if vol is not None:
                self._loaded.move_to_end(key)
                return vol
            lock = self._load_locks.setdefault(key, threading.Lock())
        with lock:
            with self._lock:
                vol = self._loaded.get(key)
            if vol is None:
                try:
                    vol = ov.spec.load()
                except IntuitfError:
                    raise
                except Exception as exc:  # a reader failing in a way it did not foresee
                    raise SessionError(
                        f"Cannot read {Path(ov.spec.source).name}: {type(exc).__name__}."
                    ) from None
                with self._lock:
                    self._loaded[key] = vol
                    while len(self._loaded) > KEEP_LOADED:
                        old, _ = self._loaded.popitem(last=False)
                        for o in self._open.values():  # its renderers go with it
                            if o.key() == old:
                                o.views.clear()
        return vol

    # -- the current TF and views ---------------------------------------------------------
    def current_tf(self, ov: OpenVolume) -> GaussianTF:
        """The volume's current TF (its histogram-aware default until one is set)."""
        if ov.tf is None:
            from intuitf.tf.defaults import default_tf

            vol = self.volume(ov)
            ov.tf = default_tf(vol.histogram()[0], value_range=vol.value_range)
        return ov.tf

    def view_renderer(self, ov: OpenVolume, background: tuple[float, float, float]):
        """The interactive renderer of the volume over ``background`` (kept per background)."""
        from intuitf.session.views import ViewRenderer

        vol = self.volume(ov)
        key = tuple(float(c) for c in background)
        with self._lock:
            vr = ov.views.get(key)
            if vr is None or vr.volume is not vol:
                vr = ViewRenderer(vol, background=key, device=self.device)
                ov.views[key] = vr
            return vr

    def describe(self, ov: OpenVolume, bins: int = 64) -> dict[str, Any]:
        """Shape, spacing, values, histogram materials and (when known) named structures."""
        from intuitf.tf.defaults import background_cutoff, find_materials

        vol = self.volume(ov)
        counts, _ = vol.histogram(256)
        lo, hi = vol.value_range
        coarse = counts.reshape(bins, -1).sum(axis=1) if 256 % bins == 0 else counts
        logc = np.log1p(coarse.astype(np.float64))
        top = float(logc.max()) or 1.0
        materials = [
            {
                "mean": round(float(m.center), 4),
                "width": round(float(m.spread), 4),
                "fraction": round(float(m.fraction), 4),
                "value": round(float(vol.to_original(float(m.center))), 4),
            }
            for m in find_materials(counts)
        ]
        summary = vol.summary()
        return {
            "id": ov.id,
            "name": vol.name,
            "source": "phantom" if ov.spec.source == PHANTOM else ov.spec.source,
            "shape_xyz": list(vol.dims),
            "spacing_xyz": list(vol.spacing),
            "extent_xyz": [round(float(e), 4) for e in vol.extent],
            "dtype": vol.original_dtype,
            "value_range": [lo, hi],
            "mean": summary["mean"],
            "notes": list(vol.notes),
            "reader_options": ov.spec.reader_options(),
            "histogram": {
                "bins": len(coarse),
                "log_counts": [round(float(v) / top, 3) for v in logc],
                "background_below": round(float(background_cutoff(counts)), 4),
                "note": "log-scaled voxel counts over the normalised range [0, 1], max 1",
            },
            "materials": materials,
            "structures": structure_map(vol),
        }


def structure_map(volume) -> dict[str, Any] | None:
    """The volume's structures (:func:`intuitf.intent.hints.structure_map_of`: materials split
    into 3-D parts with position, shape and, once a model or atlas named them, names), in a
    form an agent reads; None when the map cannot be built."""
    try:
        from intuitf.intent.hints import structure_map_of
    except ImportError:  # an intuitf without structure maps
        return None
    try:
        smap = structure_map_of(volume)
    except (IntuitfError, ValueError, MemoryError):
        return None
    out = []
    for st in smap.structures:
        lo, hi = st.value_range
        out.append(
            {
                "id": st.id,
                "name": st.name,
                "summary": st.describe(),
                "background": st.background,
                "shape": st.shape,
                "position": st.position,
                "outer": st.outer,
                "enclosed_by": st.enclosed_by,
                "share": round(float(st.share), 4),
                "value_range": [round(float(lo), 4), round(float(hi), 4)],
                "values": [
                    round(float(volume.to_original(lo)), 3),
                    round(float(volume.to_original(hi)), 3),
                ],  # fmt: skip
            }
        )
    return {
        "structures": out,
        "up_axis": "xyz"[smap.up_axis],
        "note": "value_range is normalised [0, 1] (where a Gaussian's mean goes); values are in "
        "the data's units; names appear once a model or atlas has named the parts",
    }


def _first_error(exc: ValueError) -> str:
    errors = getattr(exc, "errors", None)
    if callable(errors):
        try:
            e = errors()[0]
            return f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}"
        except Exception:  # not a pydantic error after all
            pass
    return str(exc).splitlines()[0]
