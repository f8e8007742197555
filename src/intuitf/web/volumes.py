"""The volumes the page may choose from, by id: the built-in phantom, the volumes named on the
command line, the files under ``--data``, and uploads (kept in the runs folder, size-limited).

The browser never sends a path: it names a volume by its short id, and the server maps the id
to a file it chose itself. Loaded volumes are kept (a few, least recently used dropped first).
"""

from __future__ import annotations

import json
import os
import re
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from intuitf.errors import IntuitfError
from intuitf.web.common import ApiError

#: File-name endings of the volume formats intuitf reads from a single file.
VOLUME_SUFFIXES = (
    ".raw.gz", ".raw", ".dat", ".bin", ".vol", ".nrrd", ".nhdr", ".nii.gz", ".nii", ".mha",
    ".mhd", ".vti", ".tif", ".tiff", ".npy", ".npz", ".cvol",
)  # fmt: skip
#: Of those, the ones an upload may have (a header-and-data pair cannot come in one file).
UPLOAD_SUFFIXES = tuple(s for s in VOLUME_SUFFIXES if s not in (".nhdr", ".mhd"))

_SHAPE_IN_NAME = re.compile(r"_(\d+)x(\d+)x(\d+)_([a-z]+\d*)", re.I)
_KEEP_LOADED = 4


@dataclass
class VolumeEntry:
    """One volume the page can use. ``source`` is what :func:`load_volume` reads."""

    id: str
    name: str
    source: str
    kind: str  # "builtin" | "data" | "arg" | "upload"
    options: dict[str, Any] = field(default_factory=dict)
    shape: list[int] | None = None
    dtype: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "name": self.name,
            "shape": self.shape,
            "dtype": self.dtype,
            "source": self.kind,
            "spacing": list(self.options["spacing"]) if self.options.get("spacing") else None,
        }

    def spec(self):
        """The :class:`~intuitf.session.spec.VolumeSpec` a run of this volume records."""
        from intuitf.session.spec import VolumeSpec

        return VolumeSpec(source=self.source, **self.options)


def _stem(path: Path) -> str:
    name = path.name
    for s in VOLUME_SUFFIXES:
        if name.lower().endswith(s):
            return name[: -len(s)]
    return path.stem


def slug(text: str) -> str:
    s = _SHAPE_IN_NAME.split(text)[0] if _SHAPE_IN_NAME.search(text) else text
    s = re.sub(r"[^a-z0-9]+", "-", s.lower()).strip("-")
    return s[:40] or "volume"


def _shape_from_name(name: str) -> tuple[list[int] | None, str | None]:
    m = _SHAPE_IN_NAME.search(name)
    if not m:
        return None, None
    return [int(m.group(1)), int(m.group(2)), int(m.group(3))], m.group(4).lower()


def _loaded_key(entry: VolumeEntry) -> str:
    """The key of an entry's loaded volume: its id and the options it was read with, so that
    a load still going when the options change (a new spacing) is never taken for the new one."""
    return entry.id + "|" + json.dumps(entry.options, sort_keys=True, default=str)


class VolumeCatalog:
    """Volumes by id, loaded on demand (thread-safe)."""

    def __init__(
        self,
        args: list[str] | tuple[str, ...] = (),
        data_dir: str | os.PathLike | None = None,
        upload_dir: str | os.PathLike | None = None,
        max_dim: int | None = None,
        spacing: tuple[float, float, float] | None = None,
    ) -> None:
        self.data_dir = Path(data_dir) if data_dir else None
        self.upload_dir = Path(upload_dir) if upload_dir else None
        self.max_dim = max_dim
        #: Voxel size given on the command line (serve --spacing): every file volume's.
        self.spacing = tuple(float(v) for v in spacing) if spacing else None
        self._lock = threading.RLock()
        self._entries: dict[str, VolumeEntry] = {}
        self._loaded: OrderedDict[str, Any] = OrderedDict()
        self._load_locks: dict[str, threading.Lock] = {}
        # What is built from a volume, keyed as the loaded volumes (_loaded_key).
        self._histograms: dict[str, dict] = {}
        self._structures: dict[str, list[dict]] = {}
        self._cameras: dict[str, dict] = {}
        # One structure map built at a time per volume: the Features labels and the preview's
        # view both ask for it when a volume is chosen, and two builds would share two cores.
        self._map_locks: dict[str, threading.Lock] = {}
        self._add(
            VolumeEntry(
                "phantom", "phantom", "builtin:phantom", "builtin", {}, [96, 96, 96], "uint8"
            )
        )
        for a in args:
            if a in ("phantom", "builtin:phantom"):
                continue
            self._add_file(Path(a).expanduser().resolve(), "arg")
        self.rescan()

    # -- the list -------------------------------------------------------------------------
    def _options(self) -> dict[str, Any]:
        out: dict[str, Any] = {"max_dim": self.max_dim} if self.max_dim else {}
        if self.spacing:
            out["spacing"] = list(self.spacing)
        return out

    def set_spacing(self, volume_id: str, spacing: list[float] | None) -> VolumeEntry:
        """Give a file volume its voxel size (x, y, z), or None for the file's own; new runs
        and views of it use that (runs made before keep the spacing they recorded)."""
        entry = self.get(volume_id)
        if entry.kind == "builtin":
            raise ApiError(409, "The built-in phantom's voxels are cubes; its spacing is fixed.")
        if spacing is not None:
            if len(spacing) != 3 or not all(0 < float(v) < 1e6 for v in spacing):
                raise ApiError(
                    422, "A spacing is three positive numbers [x, y, z].", "E.g. [1, 1, 2.5]."
                )
            spacing = [float(v) for v in spacing]
        with self._lock:
            if spacing is None:
                entry.options.pop("spacing", None)
            else:
                entry.options["spacing"] = spacing
            self._forget(entry.id)
        return entry

    def _add(self, entry: VolumeEntry) -> VolumeEntry:
        base, k = entry.id, 1
        while entry.id in self._entries and self._entries[entry.id].source != entry.source:
            k += 1
            entry.id = f"{base}-{k}"
        self._entries.setdefault(entry.id, entry)
        return self._entries[entry.id]

    def _add_file(self, path: Path, kind: str) -> VolumeEntry:
        with self._lock:
            for e in self._entries.values():
                if e.source == str(path):
                    return e
            shape, dtype = _shape_from_name(path.name)
            stem = _stem(path)
            return self._add(
                VolumeEntry(slug(stem), stem, str(path), kind, self._options(), shape, dtype)
            )

    def rescan(self) -> None:
        """Pick up files added under ``--data`` and the upload folder since the last look."""
        for folder, kind in ((self.data_dir, "data"), (self.upload_dir, "upload")):
            if folder is None or not folder.is_dir():
                continue
            try:
                files = sorted(folder.iterdir())
            except OSError:
                continue
            for p in files:
                if p.name.startswith(".") or not p.is_file():
                    continue
                if p.name.lower().endswith(VOLUME_SUFFIXES):
                    self._add_file(p.resolve(), kind)

    def entries(self) -> list[VolumeEntry]:
        self.rescan()
        with self._lock:
            return list(self._entries.values())

    def get(self, volume_id: Any) -> VolumeEntry:
        if not isinstance(volume_id, str) or volume_id not in self._entries:
            self.rescan()
        entry = self._entries.get(volume_id) if isinstance(volume_id, str) else None
        if entry is None:
            raise ApiError(
                404,
                f"There is no volume {str(volume_id)[:80]!r}.",
                "Choose a volume id from GET /api/volumes (or upload the file).",
            )
        return entry

    def entry_for_source(self, source: str, options: dict | None = None) -> VolumeEntry | None:
        opts = {k: v for k, v in (options or {}).items() if v is not None}
        with self._lock:
            for e in self._entries.values():
                if e.source == source and e.options == opts:
                    return e
                if source in ("phantom", "builtin:phantom") and e.id == "phantom" and not opts:
                    return e
        return None

    # -- loading --------------------------------------------------------------------------
    def load(self, volume_id: str):
        """The loaded volume (blocking: call it from a worker thread)."""
        entry = self.get(volume_id)
        with self._lock:
            key, spec = _loaded_key(entry), entry.spec()
        return self._load_key(key, spec.load, entry)

    def load_spec(self, spec):
        """The volume of a run's :class:`VolumeSpec` (shared with the catalog's when the same)."""
        opts = spec.reader_options()
        entry = self.entry_for_source(spec.source, opts)
        if entry is not None:
            return self.load(entry.id)
        key = "spec:" + json.dumps([spec.source, opts], sort_keys=True, default=str)
        return self._load_key(key, spec.load, None)

    def _load_key(self, key: str, load, entry: VolumeEntry | None):
        with self._lock:
            vol = self._loaded.get(key)
            if vol is not None:
                self._loaded.move_to_end(key)
                return vol
            lock = self._load_locks.setdefault(key, threading.Lock())
        with lock:  # one load per volume at a time; the others wait for it
            with self._lock:
                vol = self._loaded.get(key)
            if vol is None:
                vol = load()
                with self._lock:
                    self._loaded[key] = vol
                    while len(self._loaded) > _KEEP_LOADED:
                        self._loaded.popitem(last=False)
                    if entry is not None:
                        entry.shape = list(vol.dims)
                        entry.dtype = str(vol.original_dtype)
        return vol

    def _forget(self, volume_id: str) -> None:
        """Drop what was loaded or computed for a volume (under the lock): its voxels, and
        what a new voxel size changes (the preview camera frames the box)."""
        for store in (self._loaded, self._histograms, self._structures, self._cameras):
            for key in [k for k in store if k.split("|", 1)[0] == volume_id]:
                del store[key]

    def _kept(self, store: dict, volume_id: str, build: Callable[[], Any]) -> Any:
        """What ``build()`` (run outside the lock) gives for a volume, built the first time
        for its current options (a build begun before a new spacing is kept under the old)."""
        entry = self.get(volume_id)
        with self._lock:
            key = _loaded_key(entry)
            got = store.get(key)
        if got is not None:
            return got
        out = build()
        with self._lock:
            store[key] = out
        return out

    def histogram(self, volume_id: str) -> dict:
        """``{counts (log-scaled, max 1), value_range, materials}`` (blocking)."""

        def build() -> dict:
            from intuitf.tf.defaults import find_materials

            vol = self.load(volume_id)
            counts, _ = vol.histogram(256)
            logc = np.log1p(counts.astype(np.float64))
            top = float(logc.max()) or 1.0
            return {
                "counts": [round(float(v) / top, 5) for v in logc],
                "value_range": [float(v) for v in vol.value_range],
                "materials": [
                    {"mean": float(m.center), "width": float(m.spread),
                     "fraction": float(m.fraction)}
                    for m in find_materials(counts)
                ],
            }  # fmt: skip

        return self._kept(self._histograms, volume_id, build)

    def structures(self, volume_id: str) -> list[dict]:
        """The foreground structures of a volume (kept per volume; blocking)."""

        def build() -> list[dict]:
            from intuitf.intent.hints import structure_map_of

            # The map runs of this volume use (named by a model where one named its parts).
            with self._map_lock(volume_id):
                smap = structure_map_of(self.load(volume_id))
            return [
                {"id": s.id, "name": s.name, "shape": s.shape, "position": s.position,
                 "outer": s.outer, "share": float(s.share),
                 "value_range": [float(s.value_range[0]), float(s.value_range[1])]}
                for s in smap.foreground()
            ]  # fmt: skip

        return self._kept(self._structures, volume_id, build)

    def camera(self, volume_id: str) -> dict:
        """The camera a new run of this volume judges from when nothing chooses one (the view
        that shows the object upright, :func:`intuitf.session.building.default_camera`): the
        page previews the volume from it (kept per volume; blocking)."""

        def build() -> dict:
            from intuitf.session.building import default_camera

            with self._map_lock(volume_id):
                return default_camera(self.load(volume_id))

        return self._kept(self._cameras, volume_id, build)

    def _map_lock(self, volume_id: str) -> threading.Lock:
        with self._lock:
            return self._map_locks.setdefault(volume_id, threading.Lock())

    # -- uploads --------------------------------------------------------------------------
    def delete_upload(self, volume_id: str, used_by: list[str]) -> None:
        """Remove an uploaded volume (blocking). Only uploads can go, and only while no run
        was made from them (``used_by``: the runs that were), so no run loses its volume."""
        entry = self.get(volume_id)
        if entry.kind != "upload":
            raise ApiError(
                409,
                f"{entry.id!r} is not an upload; only uploaded volumes can be deleted here.",
                "Remove the file from the --data folder or the command line instead.",
            )
        if used_by:
            shown = ", ".join(used_by[:5]) + (" …" if len(used_by) > 5 else "")
            raise ApiError(
                409,
                f"Runs were made from {entry.id!r} ({shown}); deleting it would lose their volume.",
                "Delete those runs first.",
            )
        with self._lock:
            Path(entry.source).unlink(missing_ok=True)
            self._entries.pop(entry.id, None)
            self._forget(entry.id)

    def save_upload(self, filename: str, data: bytes) -> VolumeEntry:
        """Keep an uploaded volume file and check that it loads (blocking).

        The file name only chooses the reader and the id; the server picks where it goes.
        """
        if self.upload_dir is None:
            raise ApiError(403, "This server does not take volume uploads.")
        base = Path(filename or "").name
        low = base.lower()
        suffix = next((s for s in UPLOAD_SUFFIXES if low.endswith(s)), None)
        if suffix is None:
            raise ApiError(
                422,
                f"{base or 'The file'}: not a volume format intuitf reads from one file.",
                f"Upload one of: {', '.join(UPLOAD_SUFFIXES)} (a raw file's name gives its "
                "shape and type, e.g. head_256x256x128_uint8.raw).",
            )
        stem = re.sub(r"[^A-Za-z0-9_.-]+", "-", base[: -len(suffix)]).strip("-.")[:80] or "upload"
        self.upload_dir.mkdir(parents=True, exist_ok=True)
        with self._lock:
            target, k = self.upload_dir / f"{stem}{suffix}", 1
            while target.exists():
                k += 1
                target = self.upload_dir / f"{stem}-{k}{suffix}"
            target.write_bytes(data)
        try:
            from intuitf.volume import load_volume

            vol = load_volume(target, **self._options())
        except IntuitfError as exc:
            target.unlink(missing_ok=True)
            message = exc.message.replace(str(target), base)
            raise ApiError(422, message, exc.hint) from None
        except Exception as exc:  # a reader that fails in a way it did not foresee
            target.unlink(missing_ok=True)
            raise ApiError(
                422, f"{base}: cannot read this volume ({type(exc).__name__})."
            ) from None
        entry = self._add_file(target.resolve(), "upload")
        with self._lock:
            self._loaded[_loaded_key(entry)] = vol
            entry.shape, entry.dtype = list(vol.dims), str(vol.original_dtype)
        return entry
