"""``load_volume``: read any supported file into a :class:`Volume`.

Conventions, the same for every format:

* **Orientation.** The array is ``data[z, y, x]`` with x varying fastest; ``spacing`` is along
  (x, y, z). For formats with a header (NRRD, NIfTI, MetaImage, VTK image data) the file's
  *first* index is x. Orientation matrices (NIfTI affine, NRRD space directions, DICOM
  orientation) are not applied beyond that: the grid is kept in the order it was stored, and
  spacing is the length of each axis' step. DICOM slices are ordered along the slice normal.
  NumPy arrays (.npy/.npz) are taken as already ``[z, y, x]``, as a ``Volume`` stores them.
* **Values.** ``original_dtype`` is the stored type (after DICOM rescaling). ``value_range``
  is the data's own finite minimum and maximum, in the file's units (Hounsfield units for
  rescaled DICOM), for integer and float data alike: exported transfer functions then speak
  the data's units, and no part of [0, 1] is spent on values that never occur. For integer
  data ``lut_size`` is one entry per integer value in that range (at most 4096).
* **User overrides.** ``spacing`` replaces the file's spacing. ``shape``, ``dtype`` and
  ``byte_order`` describe headerless files (raw); formats with a header ignore them (noted).
  A raw file's sidecar (``NAME.json`` or a detached ``.nhdr`` header pointing at it) gives
  what the options do not; see :mod:`intuitf.volume.readers.sidecar`.
* **Downsampling.** ``max_dim`` shrinks volumes whose largest axis exceeds it (anti-aliased,
  extent kept, spacing adjusted) and says so in ``notes``. The value range stays that of the
  full-resolution data.
"""

from __future__ import annotations

import errno
import gzip
import importlib
import os
import stat
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from intuitf.errors import VolumeError
from intuitf.volume.request import RawArray, ReadRequest
from intuitf.volume.resample import downsample
from intuitf.volume.volume import Volume, scan_values

#: Names that mean the built-in phantom rather than a file.
PHANTOM_NAMES = ("builtin:phantom", "phantom")

SUPPORTED = (
    ".raw, .raw.gz (headerless; shape and type from the name or --shape/--dtype), "
    ".nrrd, .nhdr, .nii, .nii.gz, .mha, .mhd, .vti, .tif/.tiff (multi-page), .npy, .npz, "
    ".cvol, a folder of DICOM files or of TIFF slices, or 'phantom'"
)


#: File-name endings and the reader module (under ``intuitf.volume.readers``) for each.
#: ``True`` marks the reader that takes the raw-only options (shape, dtype, byte order).
_FORMATS: list[tuple[tuple[str, ...], str, bool]] = [
    ((".raw", ".raw.gz", ".dat", ".bin", ".vol"), "raw", True),
    ((".nrrd", ".nhdr"), "nrrd_reader", False),
    ((".nii", ".nii.gz"), "nifti", False),
    ((".mha", ".mhd"), "metaimage", False),
    ((".vti",), "vti", False),
    ((".tif", ".tiff"), "tiff", False),
    ((".npy", ".npz"), "npy", False),
    ((".cvol",), "cvol", False),
    ((".dcm", ".dicom", ".ima"), "dicom", False),
]


def _reader_for(path: Path) -> tuple[Callable[[ReadRequest], RawArray], bool]:
    """The reader's ``read`` for ``path`` and whether it takes the raw-only options."""
    if path.is_dir():
        files = [q for q in path.iterdir() if q.is_file() and not q.name.startswith(".")]
        if files and all(q.name.lower().endswith((".tif", ".tiff")) for q in files):
            return _module("tiff").read, False
        return _module("dicom").read, False
    low = path.name.lower()
    for suffixes, module, raw_opts in _FORMATS:
        if low.endswith(suffixes):
            return _module(module).read, raw_opts
    raise VolumeError(
        f"{path}: unknown volume format {''.join(path.suffixes) or '(no extension)'!r}.",
        f"Supported: {SUPPORTED}. A headerless file can be read as raw by renaming it to "
        "*.raw and passing --shape X,Y,Z --dtype TYPE.",
    )


def _module(name: str):
    # Imported on demand: a user reading a .raw file does not pay for importing nibabel.
    return importlib.import_module(f"intuitf.volume.readers.{name}")


def load_volume(
    path: str | os.PathLike,
    *,
    shape: tuple[int, int, int] | None = None,
    dtype: str | None = None,
    byte_order: str | None = None,
    spacing: tuple[float, float, float] | None = None,
    max_dim: int | None = None,
    name: str | None = None,
) -> Volume:
    """Read a volume file (or folder) into a :class:`Volume`, choosing the reader by its name.

    ``shape`` is (X, Y, Z), ``spacing`` is (x, y, z). ``"phantom"`` or ``"builtin:phantom"``
    gives the built-in phantom (a file of that name in the working directory wins over the bare
    word). Every problem a user can cause raises :class:`~intuitf.errors.VolumeError` with a
    message naming the file and a hint saying what to do. See the module docstring for the
    orientation and value-range conventions.
    """
    text = os.fspath(path)
    if max_dim is not None and int(max_dim) < 2:
        raise VolumeError(f"max_dim must be at least 2, got {max_dim}.", "Pass --max-dim 128.")
    if text == PHANTOM_NAMES[0] or (text == PHANTOM_NAMES[1] and not Path(text).exists()):
        from intuitf.volume.phantom import phantom

        vol = phantom()
        return _finish_phantom(vol, spacing, max_dim, name)

    p = Path(text).expanduser()
    _check_path(p)
    reader, raw_opts = _reader_for(p)
    req = ReadRequest(
        path=p,
        shape=tuple(int(v) for v in shape) if shape is not None else None,  # type: ignore[arg-type]
        dtype=dtype,
        byte_order=byte_order,
        spacing=spacing,
        max_dim=int(max_dim) if max_dim is not None else None,
    )
    try:
        got = reader(req)
    except VolumeError:
        raise
    except MemoryError:
        raise VolumeError(
            f"{p}: ran out of memory while reading.", "Pass --max-dim 256 to downsample."
        ) from None
    except (
        OSError,
        EOFError,
        zlib.error,
        gzip.BadGzipFile,
        ValueError,
        KeyError,
        IndexError,
        StopIteration,
        struct.error,
    ) as exc:
        raise VolumeError(
            f"{p}: the file could not be read; it may be truncated or corrupt ({exc}).",
            "Check that the file is complete and of the type its extension says.",
        ) from None
    notes = list(got.notes)
    if not raw_opts:
        ignored = [
            f"{k}={v}"
            for k, v in (("shape", shape), ("dtype", dtype), ("byte_order", byte_order))
            if v is not None
        ]
        if ignored:
            notes.append(f"Ignored {', '.join(ignored)}: the file's header describes it.")
    return _finish(got, req, notes, name or got.name or _default_name(p), raw_opts)


def _check_path(p: Path) -> None:
    """Raise :class:`VolumeError` saying why ``p`` cannot be read: missing, a symbolic-link
    loop, unreadable, or an empty file."""
    try:
        st = p.stat()
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise VolumeError(
                f"{p}: a loop of symbolic links (it points back to itself); there is no file "
                "behind it.",
                f"Check where it points with `ls -l {p}` and link it to the real file.",
            ) from None
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            hint = "Check the path."
            if p.is_symlink():
                hint = f"{p} is a symbolic link to {os.readlink(p)}, which does not exist."
            elif p.parent.is_dir():
                near = sorted(q.name for q in p.parent.iterdir() if q.name[:3] == p.name[:3])[:5]
                if near:
                    hint += " Files with a similar name: " + ", ".join(near) + "."
            raise VolumeError(f"{p}: no such file or folder.", hint) from None
        raise VolumeError(
            f"{p}: cannot be opened ({exc.strerror or exc}).", "Check the path and its permissions."
        ) from None
    except RuntimeError:  # Python < 3.13 reports a symlink loop from resolve() this way
        raise VolumeError(f"{p}: a loop of symbolic links.", "Link it to the real file.") from None
    if stat.S_ISREG(st.st_mode) and st.st_size == 0:
        raise VolumeError(
            f"{p}: the file is empty (0 bytes).",
            "It was probably not copied or downloaded completely; get the file again.",
        )


def _default_name(p: Path) -> str:
    from intuitf.volume.readers.raw import strip_suffixes

    n = p.name
    for suf in (".nii.gz", ".nrrd", ".nhdr", ".nii", ".mha", ".mhd", ".vti", ".tiff", ".tif",
                ".npy", ".npz", ".cvol", ".dcm"):  # fmt: skip
        if n.lower().endswith(suf):
            return n[: -len(suf)] or n
    return strip_suffixes(n) or n


def _no_spacing_note(path: Path, shape_zyx: tuple[int, ...], raw: bool) -> str:
    """The note for a file without voxel spacing: what follows, and exactly what fixes it."""
    z, y, x = shape_zyx
    where = ""
    if raw:
        from intuitf.volume.readers.sidecar import json_sidecar_names

        car = json_sidecar_names(path)[-1].name
        where = f', or put a sidecar {car} next to the file holding {{"spacing": [X, Y, Z]}}'
    return (
        f"The file gives no voxel spacing, so its {x}x{y}x{z} voxels are drawn as cubes "
        "(1,1,1): the picture is stretched or squashed unless they are. Give the voxel size "
        "along x, y, z with --spacing X,Y,Z (e.g. --spacing 0.5,0.5,1.0 for voxels twice as "
        f"deep as they are wide){where}."
    )


def _finish(
    got: RawArray, req: ReadRequest, notes: list[str], name: str, raw: bool = False
) -> Volume:
    a = got.array
    if a.ndim != 3:
        raise VolumeError(
            f"{req.path}: expected a 3D volume, got an array of shape {a.shape}.",
            "Pass a 3D scalar volume (one value per voxel).",
        )
    if a.size == 0:
        raise VolumeError(f"{req.path}: the volume is empty (shape {a.shape}).")
    if a.dtype.kind not in "uifb":
        raise VolumeError(
            f"{req.path}: unsupported voxel type {a.dtype}.",
            "Convert the volume to an integer or floating-point scalar type.",
        )
    spacing = req.spacing or got.spacing or (1.0, 1.0, 1.0)
    if req.spacing is None and got.spacing is None:
        notes.append(_no_spacing_note(req.path, a.shape, raw))
    spacing = tuple(float(s) for s in spacing)
    if len(spacing) != 3 or not all(np.isfinite(s) and s > 0 for s in spacing):
        raise VolumeError(
            f"{req.path}: spacing must be three positive numbers, got {spacing}.",
            "Pass --spacing X,Y,Z with positive values.",
        )
    a = a.astype(a.dtype.newbyteorder("="), copy=False) if not a.dtype.isnative else a
    z, y, x = a.shape
    if req.max_dim is not None and max(a.shape) > req.max_dim:
        scan = scan_values(a, str(req.path))
        lo, hi = scan.lo, scan.hi
        if hi > lo:  # (a constant volume is reported by from_array below)
            small, spacing = downsample(
                a, spacing, req.max_dim, fill=scan.fill, limit=scan.limit, value_range=(lo, hi)
            )
            nz, ny, nx = small.shape
            notes += scan.notes()
            notes.append(
                f"Downsampled from {x}x{y}x{z} to {nx}x{ny}x{nz} (max_dim {req.max_dim}; "
                "anti-aliased linear resampling, physical size kept)."
            )
            return Volume(
                data=small, spacing=spacing, name=name, original_dtype=a.dtype.name,
                value_range=(lo, hi), source=str(req.path), notes=notes,
            )  # fmt: skip
    vol = Volume.from_array(a, spacing=spacing, name=name, source=str(req.path))
    vol.notes = notes + vol.notes
    return vol


def _finish_phantom(vol: Volume, spacing, max_dim, name) -> Volume:
    if spacing is not None:
        vol.spacing = tuple(float(s) for s in spacing)  # type: ignore[assignment]
        vol.__post_init__()
    if max_dim is not None and max(vol.shape) > max_dim:
        lo, hi = vol.value_range
        small, sp = downsample(vol.data, vol.spacing, int(max_dim))
        vol = Volume(
            data=small, spacing=sp, name=vol.name, original_dtype=vol.original_dtype,
            value_range=(lo, hi), source=vol.source,
            notes=vol.notes + [f"Downsampled to max_dim {max_dim}."],
        )  # fmt: skip
    if name:
        vol.name = name
    return vol
