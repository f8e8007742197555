"""Headerless voxel arrays: ``.raw`` and gzip-compressed ``.raw.gz``.

The grid size and sample type come from the caller or from the file name, in the common
``<name>_<X>x<Y>x<Z>_<dtype>.raw[.gz]`` form (``foot_256x256x256_uint8.raw.gz``,
``foot_zfp8lossy_256x256x256_uint8.raw.gz``). Voxels are stored with x varying fastest, then y,
then z, so the array comes out as ``[z, y, x]``. Byte order is little-endian unless told.
Uncompressed files are memory-mapped, so downsampling a huge file reads it in slabs.

A raw file carries no voxel spacing. A sidecar next to it may give it, and the grid size, type
and byte order too: ``NAME.json`` (or ``NAME.raw.json``) or a detached NRRD header ``*.nhdr``
whose ``data file`` is this file (see :mod:`intuitf.volume.readers.sidecar`).
"""

from __future__ import annotations

import gzip
import re
import struct
import zlib
from pathlib import Path

import numpy as np

from intuitf.errors import VolumeError
from intuitf.volume.readers.sidecar import find_sidecar, json_sidecar_names
from intuitf.volume.request import RawArray, ReadRequest

#: Accepted sample-type names and the numpy kinds they mean (byte order added later).
DTYPE_ALIASES: dict[str, str] = {
    "uint8": "u1", "u8": "u1", "uchar": "u1", "ubyte": "u1",
    "int8": "i1", "i8": "i1", "char": "i1", "byte": "i1",
    "uint16": "u2", "u16": "u2", "ushort": "u2",
    "int16": "i2", "i16": "i2", "short": "i2",
    "uint32": "u4", "u32": "u4", "uint": "u4",
    "int32": "i4", "i32": "i4", "int": "i4",
    "uint64": "u8", "u64": "u8",
    "int64": "i8", "i64": "i8",
    "float16": "f2", "f16": "f2", "half": "f2",
    "float32": "f4", "f32": "f4", "float": "f4", "single": "f4",
    "float64": "f8", "f64": "f8", "double": "f8",
}  # fmt: skip

_DIMS_RE = re.compile(r"(?<![0-9])(\d+)x(\d+)x(\d+)(?![0-9])", re.IGNORECASE)
_BYTE_ORDERS = {"little": "<", "big": ">", "<": "<", ">": ">", "le": "<", "be": ">"}


def parse_dtype(text: str, byte_order: str | None = None, *, source: str = "") -> np.dtype:
    """The numpy dtype for a sample-type name (``uint8``, ``int16``, ``float32``, ...).

    ``byte_order`` is ``"little"`` (default) or ``"big"``. Unknown names raise
    :class:`VolumeError` listing the accepted ones.
    """
    key = str(text).strip().lower()
    kind = DTYPE_ALIASES.get(key)
    if kind is None:
        accepted = "uint8, int8, uint16, int16, uint32, int32, uint64, int64, float32, float64"
        where = f"{source}: " if source else ""
        raise VolumeError(
            f"{where}unknown voxel type {text!r}.",
            f"Use one of: {accepted} (e.g. --dtype uint16).",
        )
    return np.dtype(_byte_order_char(byte_order, source) + kind)


def _byte_order_char(byte_order: str | None, source: str = "") -> str:
    if byte_order is None:
        return "<"
    c = _BYTE_ORDERS.get(str(byte_order).strip().lower())
    if c is None:
        raise VolumeError(
            f"{source + ': ' if source else ''}unknown byte order {byte_order!r}.",
            "Use --byte-order little or --byte-order big.",
        )
    return c


def parse_name(filename: str) -> tuple[tuple[int, int, int] | None, str | None, str]:
    """Dims (X, Y, Z), sample-type name and a short volume name from a raw file's name.

    ``foot_zfp8lossy_256x256x256_uint8.raw.gz`` gives ``((256, 256, 256), "uint8", "foot")``.
    Missing parts come back as None.
    """
    stem = strip_suffixes(filename)
    m = _DIMS_RE.search(stem)
    dims = tuple(int(g) for g in m.groups()) if m else None
    dtype = None
    for tok in re.split(r"[_.\-\s]+", stem):
        if tok.lower() in DTYPE_ALIASES and tok.lower() not in ("int", "char", "byte", "float"):
            dtype = tok.lower()
        elif tok.lower() in ("float", "double"):
            dtype = dtype or tok.lower()
    name = stem[: m.start()] if m else stem
    name = re.sub(r"[_\-.]*zfp\d*lossy", "", name, flags=re.IGNORECASE)
    name = name.strip("_-. ") or stem
    return dims, dtype, name  # type: ignore[return-value]


def strip_suffixes(filename: str) -> str:
    """The file name without ``.raw``, ``.gz`` and similar extensions."""
    stem = Path(filename).name
    for suf in (".gz", ".raw", ".dat", ".bin", ".img", ".vol"):
        if stem.lower().endswith(suf):
            stem = stem[: -len(suf)]
    return stem


def _suggestions(actual: int, dims: tuple[int, int, int], dtype: np.dtype) -> list[str]:
    """Shapes and types that would explain a file of ``actual`` bytes."""
    out: list[str] = []
    x, y, z = dims
    n = x * y * z
    for name in ("uint8", "uint16", "int16", "float32", "float64"):
        if np.dtype(DTYPE_ALIASES[name]).itemsize * n == actual and name != dtype.name:
            out.append(f"--dtype {name} with the same shape")
    isz = dtype.itemsize
    if actual % isz == 0:
        voxels = actual // isz
        if voxels % (x * y) == 0 and voxels // (x * y) != z:
            out.append(f"--shape {x},{y},{voxels // (x * y)} ({dtype.name})")
        k = round(voxels ** (1 / 3))
        if k**3 == voxels and (k, k, k) != dims:
            out.append(f"--shape {k},{k},{k} ({dtype.name})")
    extra = actual - n * isz
    if 0 < extra <= 4096:
        out.append(f"the file may start with a {extra}-byte header this reader does not skip")
    return out


def _size_mismatch(path: Path, expected: int, actual: int, dims, dtype, compressed: bool):
    what = "decompressed size" if compressed else "size"
    sug = _suggestions(actual, dims, dtype)
    hint = "Check --shape X,Y,Z and --dtype (and that the file is complete)."
    if sug:
        hint = "Sizes that would match: " + "; ".join(sug) + ". " + hint
    shape = "x".join(str(d) for d in dims)
    return VolumeError(
        f"{path}: a {shape} {dtype.name} volume needs {expected} bytes, but the file's {what} "
        f"is {actual} bytes.",
        hint,
    )


def _gzip_isize(path: Path) -> int | None:
    """Uncompressed size mod 2**32 from a gzip trailer, or None if the file is too short."""
    with open(path, "rb") as fh:
        fh.seek(0, 2)
        if fh.tell() < 18:
            return None
        fh.seek(-4, 2)
        return struct.unpack("<I", fh.read(4))[0]


def _gzip_size(path: Path) -> tuple[int, BaseException | None]:
    """Decompressed size of a gzip file, counted by streaming it through a small buffer, and
    the error that stopped the count early (a truncated or corrupt stream), if any."""
    n = 0
    try:
        with gzip.open(path, "rb") as fh:
            while k := len(fh.read(1 << 16)):
                n += k
    except (OSError, EOFError, zlib.error) as exc:
        return n, exc
    return n, None


def _cut_off(path: Path, got: int, expected: int, dims, dtype, exc: BaseException) -> VolumeError:
    shape = "x".join(str(d) for d in dims)
    if isinstance(exc, EOFError):
        what = f"the gzip stream is cut off: the file is truncated after about {got} decompressed bytes"
    else:
        what = f"the gzip stream is corrupt after about {got} decompressed bytes ({exc})"
    return VolumeError(
        f"{path}: {what}, and a {shape} {dtype.name} volume needs {expected} bytes.",
        "Download or copy the file again; `gzip -t` checks a gzip file.",
    )


def read(request: ReadRequest) -> RawArray:
    """Read a ``.raw`` or ``.raw.gz`` file."""
    path = request.path
    name_dims, name_dtype, name = parse_name(path.name)
    car = find_sidecar(path)
    notes: list[str] = []
    spacing = None
    if car is not None:
        notes += car.notes
        told = [
            f"{what} {text}"
            for what, value, text, overridden in (
                ("shape", car.shape, "x".join(map(str, car.shape or ())), request.shape),
                ("voxel type", car.dtype, car.dtype, request.dtype),
                ("byte order", car.byte_order, car.byte_order, request.byte_order),
                (
                    "spacing",
                    car.spacing,
                    ",".join(f"{v:g}" for v in car.spacing or ()),
                    request.spacing,
                ),
            )  # fmt: skip
            if value is not None and overridden is None
        ]
        if told:
            notes.append(f"From {car.path.name}: {', '.join(told)}.")
        if car.shape and name_dims and tuple(car.shape) != tuple(name_dims) and not request.shape:
            notes.append(
                f"{car.path.name} gives the shape {'x'.join(map(str, car.shape))}, the file's "
                f"name {'x'.join(map(str, name_dims))}; the sidecar's is used."
            )
        spacing = car.spacing
    dims = request.shape or (car.shape if car else None) or name_dims
    dtype_text = request.dtype or (car.dtype if car else None) or name_dtype
    byte_order = request.byte_order or (car.byte_order if car else None)
    if dims is None or dtype_text is None:
        missing = " and ".join(
            w for w, v in (("grid size", dims), ("voxel type", dtype_text)) if v is None
        )
        raise VolumeError(
            f"{path}: a raw file has no header, and its {missing} could not be read from its name.",
            "Pass --shape X,Y,Z and --dtype (e.g. --shape 256,256,128 --dtype uint8), name "
            "the file like volume_256x256x128_uint8.raw, or put a sidecar "
            f"{json_sidecar_names(path)[-1].name} next to it holding "
            '{"shape": [256, 256, 128], "dtype": "uint8", "spacing": [1, 1, 1]}.',
        )
    dims = tuple(int(d) for d in dims)
    if len(dims) != 3 or min(dims) < 1:
        raise VolumeError(
            f"{path}: the grid size must be three positive numbers, got {dims}.",
            "Pass --shape X,Y,Z.",
        )
    dtype = parse_dtype(dtype_text, byte_order, source=str(car.path if car else path))
    x, y, z = dims
    expected = x * y * z * dtype.itemsize
    compressed = path.name.lower().endswith(".gz")
    if not compressed:
        actual = path.stat().st_size
        if actual != expected:
            raise _size_mismatch(path, expected, actual, dims, dtype, compressed=False)
        request.reserve(dims, dtype, mapped=True)
        arr = np.memmap(path, dtype=dtype, mode="r", shape=(z, y, x))
        return RawArray(arr, spacing=spacing, notes=notes, name=name)

    isize = _gzip_isize(path)
    if isize is None or isize != expected % (1 << 32):
        # The trailer disagrees with the shape, but a truncated file's last bytes are no
        # trailer at all: count the stream's real size (nothing kept in memory) and report
        # what is actually wrong.
        actual, error = _gzip_size(path)
        if error is not None:
            raise _cut_off(path, actual, expected, dims, dtype, error)
        raise _size_mismatch(path, expected, actual, dims, dtype, compressed=True)
    request.reserve(dims, dtype)
    arr = np.empty((z, y, x), dtype=dtype)
    buf = memoryview(arr.reshape(-1)).cast("B")
    got = 0
    try:
        with gzip.open(path, "rb") as fh:
            # Read straight into the array: no second copy of a large volume.
            while got < expected:
                k = fh.readinto(buf[got : min(expected, got + (64 << 20))])
                if not k:
                    break
                got += k
            extra = len(fh.read(1 << 16)) if got == expected else 0
    except (OSError, EOFError, zlib.error) as exc:
        raise _cut_off(path, got, expected, dims, dtype, exc) from None
    if got != expected or extra:
        raise _size_mismatch(path, expected, got + extra, dims, dtype, compressed=True)
    return RawArray(arr, spacing=spacing, notes=notes, name=name)
