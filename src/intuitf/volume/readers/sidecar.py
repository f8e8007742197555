"""What a headerless raw file's neighbours say about it: grid size, voxel type, byte order and,
above all, voxel spacing, which a raw file cannot carry.

Looked for next to ``NAME.raw`` (or ``NAME.raw.gz``), first found wins:

1. A JSON sidecar: ``NAME.raw.json`` (the whole file name plus ``.json``) or ``NAME.json``
   (without ``.raw`` / ``.gz``). Every key is optional::

       {"spacing": [0.5, 0.5, 1.0], "shape": [256, 256, 113], "dtype": "uint16",
        "byte_order": "little"}

   ``spacing`` is the voxel size along x, y, z; ``shape`` the grid size X, Y, Z.
2. A detached NRRD header (``*.nhdr``) in the same folder whose ``data file`` is this raw file:
   its ``sizes``, ``type``, ``endian`` and ``spacings`` (or ``space directions``) are used.

What the command line says (``--shape``, ``--dtype``, ``--byte-order``, ``--spacing``) wins
over a sidecar, and a sidecar wins over what the file's name says.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

from intuitf.errors import VolumeError

#: Keys a JSON sidecar may hold.
JSON_KEYS = ("spacing", "shape", "dtype", "byte_order")

#: Header files larger than this are not NRRD headers; more than this many are not scanned.
_MAX_HEADER_BYTES = 1 << 16
_MAX_HEADERS = 64


@dataclass
class Sidecar:
    """What a sidecar file said (None where it said nothing) and notes about reading it."""

    path: Path
    shape: tuple[int, int, int] | None = None
    dtype: str | None = None
    byte_order: str | None = None
    spacing: tuple[float, float, float] | None = None
    notes: list[str] = field(default_factory=list)


def json_sidecar_names(raw: Path) -> list[Path]:
    """Where a JSON sidecar of ``raw`` may be, in the order they are tried."""
    from intuitf.volume.readers.raw import strip_suffixes

    full = raw.with_name(raw.name + ".json")
    short = raw.with_name(strip_suffixes(raw.name) + ".json")
    return [full] if short == full else [full, short]


def find_sidecar(raw: Path) -> Sidecar | None:
    """The sidecar of the raw file ``raw``, or None. A sidecar that is there but unusable
    raises :class:`VolumeError` naming it (it was meant for this file)."""
    for p in json_sidecar_names(raw):
        if p.is_file():
            return read_json_sidecar(p)
    return find_nhdr(raw)


def _triple(value, what: str, kind: type, source: Path) -> tuple | None:
    if value is None:
        return None
    ok = isinstance(value, list | tuple) and len(value) == 3
    if ok:
        try:
            out = tuple(kind(v) for v in value)
            ok = all(not isinstance(v, bool) for v in value) and all(
                math.isfinite(v) and v > 0 for v in out
            )
            if kind is int:
                ok = ok and all(float(v) == int(v) for v in value)
        except (TypeError, ValueError):
            ok = False
    if not ok:
        raise VolumeError(
            f"{source}: '{what}' must be three positive numbers [x, y, z], got {value!r}.",
            f'Write it like "{what}": ' + ("[256, 256, 128]" if kind is int else "[0.5, 0.5, 1.0]"),
        )
    return out


def read_json_sidecar(path: Path) -> Sidecar:
    """Read a JSON sidecar (see the module notes)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise VolumeError(
            f"{path}: this sidecar is not readable JSON ({exc}).",
            'Write it like {"spacing": [0.5, 0.5, 1.0]}, or remove it.',
        ) from None
    if not isinstance(data, dict):
        raise VolumeError(
            f"{path}: a sidecar must be a JSON object, got {type(data).__name__}.",
            'Write it like {"spacing": [0.5, 0.5, 1.0]}.',
        )
    car = Sidecar(path)
    car.spacing = _triple(data.get("spacing"), "spacing", float, path)
    car.shape = _triple(data.get("shape"), "shape", int, path)
    for key in ("dtype", "byte_order"):
        value = data.get(key)
        if value is not None and not isinstance(value, str):
            raise VolumeError(f"{path}: '{key}' must be a string, got {value!r}.")
    car.dtype = data.get("dtype")
    car.byte_order = data.get("byte_order")
    unknown = sorted(set(data) - set(JSON_KEYS))
    if unknown:
        car.notes.append(
            f"{path.name}: ignored unknown key(s) {', '.join(unknown)} (known: "
            f"{', '.join(JSON_KEYS)})."
        )
    return car


def _nhdr_candidates(raw: Path) -> list[Path]:
    from intuitf.volume.readers.raw import strip_suffixes

    same = raw.with_name(strip_suffixes(raw.name) + ".nhdr")
    try:
        others = sorted(
            q for q in raw.parent.iterdir() if q.suffix.lower() == ".nhdr" and q != same
        )
    except OSError:
        others = []
    return ([same] if same.is_file() else []) + others[:_MAX_HEADERS]


def _data_file(header: dict, nhdr: Path) -> Path | None:
    name = header.get("data file") or header.get("datafile")
    if not isinstance(name, str) or name.split()[0].upper() == "LIST" or "%" in name:
        return None
    p = Path(name)
    return p if p.is_absolute() else nhdr.parent / p


def find_nhdr(raw: Path) -> Sidecar | None:
    """A detached NRRD header next to ``raw`` whose data file is ``raw``, read as a sidecar."""
    import nrrd
    import numpy as np

    from intuitf.volume.readers.nrrd_reader import _spacing

    try:
        target = raw.resolve()
    except (OSError, RuntimeError):
        return None
    for nhdr in _nhdr_candidates(raw):
        try:
            if nhdr.stat().st_size > _MAX_HEADER_BYTES:
                continue
            header = nrrd.read_header(str(nhdr))
        except (OSError, StopIteration, ValueError, nrrd.NRRDError):
            continue
        data = _data_file(header, nhdr)
        try:
            if data is None or data.resolve() != target:
                continue
        except (OSError, RuntimeError):
            continue
        car = Sidecar(nhdr)
        sizes = [int(s) for s in header.get("sizes", [])]
        if len(sizes) != 3:
            raise VolumeError(
                f"{nhdr}: describes {raw.name} with {len(sizes)} axes {sizes}; a volume has 3.",
                f"Fix the header's sizes, or move {nhdr.name} away.",
            )
        car.shape = tuple(sizes)  # type: ignore[assignment]
        try:
            dt = np.dtype(nrrd.reader._determine_datatype(header))
        except Exception:  # an unknown type name: let the file name or --dtype decide
            dt = None
        if dt is not None:
            car.dtype = dt.newbyteorder("=").name
            car.byte_order = "big" if dt.byteorder == ">" else "little"
        car.spacing = _spacing(header)
        encoding = str(header.get("encoding", "raw")).lower()
        gz = raw.name.lower().endswith(".gz")
        expected = ("gzip", "gz") if gz else ("raw",)
        skips = any(int(header.get(k, 0) or 0) != 0 for k in ("byte skip", "line skip"))
        if encoding not in expected or skips:
            raise VolumeError(
                f"{raw}: its header {nhdr.name} says encoding '{encoding}'"
                + (" with bytes to skip" if skips else "")
                + ", which reading the data file directly does not handle.",
                f"Open the header instead: pass {nhdr} as the volume.",
            )
        return car
    return None
