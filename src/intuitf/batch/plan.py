"""Which volumes a batch covers: files, folders and globs, expanded to one item per volume.

- a file of a known volume format is one volume (a ``.dcm`` file: the series it belongs to);
- a folder of DICOM files is one volume *per series* (a study folder with a scout, a soft-tissue
  and a bone series gives three), read through one file of the series;
- a folder of TIFF slices is one volume, as ``intuitf optimize`` reads it;
- any other folder is searched (recursively) for volume files and the folders above;
- a glob (``scans/*.nii.gz``, ``study/**/``) is expanded and each match taken as above;
- ``phantom`` is the built-in phantom.

A path that does not exist is kept: its volume fails to load, is reported and skipped. Each
item gets a key, a folder name that stays the same when the same command runs again (so a
rerun finds its runs): the file's stem, made unique with a short hash of the full path when two
volumes share a stem.
"""

from __future__ import annotations

import glob
import hashlib
import re
from dataclasses import asdict, dataclass
from pathlib import Path

from intuitf.errors import IntuitfError

#: File endings read as one volume each (a folder of only .tif/.tiff is a slice stack).
VOLUME_SUFFIXES = (
    ".raw", ".raw.gz", ".nrrd", ".nhdr", ".nii", ".nii.gz", ".mha", ".mhd", ".vti",
    ".npy", ".npz", ".cvol", ".tif", ".tiff",
)  # fmt: skip
DICOM_SUFFIXES = (".dcm", ".dicom", ".ima")
_GLOB = re.compile(r"[*?\[]")


@dataclass(frozen=True)
class VolumeItem:
    """One volume of the batch: its run folder name, where to read it, and how to call it."""

    key: str
    source: str
    label: str
    kind: str = "file"  # "file" | "dicom-series" | "slices" | "phantom" | "missing"
    series: str | None = None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> VolumeItem:
        return cls(**{k: d.get(k) for k in ("key", "source", "label", "kind", "series")})


def _stem(name: str) -> str:
    low = name.lower()
    for suf in sorted(VOLUME_SUFFIXES + DICOM_SUFFIXES, key=len, reverse=True):
        if low.endswith(suf):
            return name[: -len(suf)]
    return Path(name).stem or name


def _safe(text: str) -> str:
    s = re.sub(r"[^A-Za-z0-9._-]+", "-", text).strip("-.")
    return s[:80] or "volume"


def _is_volume_file(p: Path) -> bool:
    return p.name.lower().endswith(VOLUME_SUFFIXES) and not p.name.startswith(".")


def _dicom_series(folder: Path) -> list[tuple[str, Path, str, int]]:
    """(series uid, one file of it, description, slices) for each DICOM series in ``folder``."""
    import pydicom
    from pydicom.errors import InvalidDicomError

    series: dict[str, list] = {}
    for p in sorted(folder.iterdir()):
        if not p.is_file() or p.name.startswith(".") or _is_volume_file(p):
            continue
        try:
            ds = pydicom.dcmread(p, stop_before_pixels=True)
        except (InvalidDicomError, OSError, EOFError, ValueError, TypeError, AttributeError):
            continue
        if "Rows" not in ds or "Columns" not in ds:
            continue
        uid = str(ds.get("SeriesInstanceUID", ""))
        entry = series.setdefault(uid, [p, ds, 0])
        entry[2] += 1
    out = []
    for uid, (p, ds, n) in series.items():
        desc = str(ds.get("SeriesDescription", "") or "").strip()
        number = ds.get("SeriesNumber")
        label = desc or (f"series {number}" if number is not None else uid[-8:] or "series")
        out.append((uid, p, label, n))
    return out


def _expand_folder(folder: Path, out: list[tuple]) -> None:
    files = [q for q in sorted(folder.iterdir()) if q.is_file() and not q.name.startswith(".")]
    if files and all(q.name.lower().endswith((".tif", ".tiff")) for q in files) and len(files) > 1:
        out.append(("slices", folder, folder.name, None))
        return
    for q in files:
        if _is_volume_file(q):
            out.append(("file", q, q.name, None))
    multi = _dicom_series(folder)
    for uid, p, label, _n in sorted(multi, key=lambda s: (s[2], s[0])):
        name = folder.name if len(multi) == 1 else f"{folder.name} {label}"
        out.append(("dicom-series", p, name, uid))
    for sub in sorted(q for q in folder.iterdir() if q.is_dir() and not q.name.startswith(".")):
        _expand_folder(sub, out)


def _expand_one(text: str, out: list[tuple]) -> None:
    if text in ("phantom", "builtin:phantom") and not Path(text).exists():
        out.append(("phantom", text, "phantom", None))
        return
    p = Path(text).expanduser()
    if p.is_dir():
        before = len(out)
        _expand_folder(p, out)
        if len(out) == before:
            raise IntuitfError(
                f"{p}: no volumes found in this folder.",
                "Point at volume files, a folder holding them, or a folder of DICOM series.",
            )
    elif p.is_file() and p.name.lower().endswith(DICOM_SUFFIXES):
        import pydicom

        try:
            uid = pydicom.dcmread(p, stop_before_pixels=True).get("SeriesInstanceUID")
        except Exception:  # unreadable: let loading report it
            uid = None
        out.append(("dicom-series", p, p.parent.name, str(uid) if uid else None))
    else:
        out.append(("file" if p.exists() else "missing", p, p.name, None))


def plan_volumes(inputs: list[str]) -> list[VolumeItem]:
    """The batch's volumes, in the order given (globs sorted), each once."""
    found: list[tuple] = []
    for text in inputs:
        text = str(text)
        if _GLOB.search(text) and not Path(text).exists():
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                raise IntuitfError(
                    f"{text}: no file or folder matches this pattern.",
                    "Check the pattern (quote it so the shell leaves it to intuitf).",
                )
            for m in matches:
                if (
                    Path(m).is_dir()
                    or _is_volume_file(Path(m))
                    or m.lower().endswith(DICOM_SUFFIXES)
                ):
                    _expand_one(m, found)
        else:
            _expand_one(text, found)
    items: list[tuple] = []
    seen: set[tuple[str, str | None]] = set()
    for kind, path, label, series in found:
        source = str(path) if kind == "phantom" else str(Path(path).absolute())
        ident = (source if kind != "dicom-series" else str(Path(source).parent), series)
        if ident in seen:
            continue
        seen.add(ident)
        items.append((kind, source, label, series))
    if not items:
        raise IntuitfError("No volumes to process.", "Give volume files, folders or globs.")
    return _keyed(items)


def _keyed(items: list[tuple]) -> list[VolumeItem]:
    stems = []
    for kind, source, label, _series in items:
        if kind == "phantom":
            stems.append("phantom")
        elif kind in ("dicom-series", "slices"):
            stems.append(_safe(label))
        else:
            stems.append(_safe(_stem(Path(source).name)))
    counts: dict[str, int] = {}
    for s in stems:
        counts[s] = counts.get(s, 0) + 1
    out = []
    used: set[str] = set()
    for (kind, source, label, series), stem in zip(items, stems, strict=True):
        key = stem
        if counts[stem] > 1 or key in used:
            h = hashlib.sha256(f"{source}|{series or ''}".encode()).hexdigest()[:6]
            key = f"{stem}-{h}"
        used.add(key)
        out.append(VolumeItem(key=key, source=source, label=label, kind=kind, series=series))
    return out
