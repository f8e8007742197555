"""Reading and writing pictures (PNG and JPEG out; PNG, JPEG, ... in) with Pillow.

Every rendering intuitf writes carries a small record of how it was made, so a sketch drawn on
it can be judged from the same view: the camera (:meth:`Camera.to_dict`), the picture size and
the volume's name, as JSON in a PNG ``tEXt`` chunk with the key ``intuitf`` (in a JPEG, a
comment that starts with ``intuitf:``). :func:`read_render_metadata` reads it back.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image, UnidentifiedImageError
from PIL.PngImagePlugin import PngInfo

from intuitf.errors import IntuitfError


class ImageError(IntuitfError):
    """A picture could not be read or written."""


def _as_uint8(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (1, 3, 4)):
        raise ImageError(f"An image must be (H, W), (H, W, 3) or (H, W, 4), got shape {a.shape}.")
    if a.dtype != np.uint8:
        if a.dtype.kind != "f":
            raise ImageError(f"An image must be uint8 or float in [0, 1], got {a.dtype}.")
        a = np.clip(np.nan_to_num(a) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    return np.ascontiguousarray(a)


#: The PNG text key (and JPEG comment prefix) of a rendering's record.
METADATA_KEY = "intuitf"

#: File-name suffixes :func:`save_image` writes, and the format of each.
IMAGE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG"}


def render_record(
    camera: Any,
    size: tuple[int, int] | int,
    volume: str | None = None,
    **extra: Any,
) -> dict:
    """The record a rendering carries: ``camera`` (a Camera or its dict), ``size`` (width,
    height) in pixels, the volume's name, and any ``extra`` facts (shading, background ...)."""
    cam = camera.to_dict() if hasattr(camera, "to_dict") else dict(camera)
    w, h = (size, size) if isinstance(size, int) else size
    rec = {"camera": cam, "size": [int(w), int(h)], "volume": volume}
    rec.update(extra)
    return rec


def _encode(image: np.ndarray, fmt: str, metadata: Mapping | None) -> bytes:
    buf = io.BytesIO()
    img = Image.fromarray(_as_uint8(image))
    text = json.dumps(metadata, sort_keys=True) if metadata is not None else None
    if fmt == "PNG":
        info = None
        if text is not None:
            info = PngInfo()
            info.add_text(METADATA_KEY, text)
        img.save(buf, format="PNG", pnginfo=info)
    else:
        kw: dict[str, Any] = {"quality": 95}
        if text is not None:
            kw["comment"] = f"{METADATA_KEY}:{text}".encode()
        img.convert("RGB").save(buf, format=fmt, **kw)
    return buf.getvalue()


def png_bytes(image: np.ndarray, metadata: Mapping | None = None) -> bytes:
    """The image (uint8, or float in [0, 1]) encoded as PNG; ``metadata`` (JSON-able, e.g.
    :func:`render_record`) goes into a ``tEXt`` chunk named ``intuitf``."""
    return _encode(image, "PNG", metadata)


def image_format(path: str | os.PathLike) -> str:
    """The format :func:`save_image` writes for ``path``'s suffix; ImageError for others."""
    suffix = Path(path).suffix.lower()
    fmt = IMAGE_FORMATS.get(suffix)
    if fmt is None:
        raise ImageError(
            f"{path}: cannot write a picture with the suffix {suffix or '(none)'!r}.",
            f"Use one of: {', '.join(IMAGE_FORMATS)}.",
        )
    return fmt


def save_image(image: np.ndarray, path: str | os.PathLike, metadata: Mapping | None = None) -> Path:
    """Write ``image`` as PNG or JPEG, as ``path``'s suffix says (others are refused),
    atomically: a crash never leaves half a file at ``path``."""
    return _write_atomic(Path(path), _encode(image, image_format(path), metadata))


def save_png(image: np.ndarray, path: str | os.PathLike, metadata: Mapping | None = None) -> Path:
    """Write ``image`` as a PNG atomically: a crash never leaves half a file at ``path``."""
    return _write_atomic(Path(path), png_bytes(image, metadata))


def read_render_metadata(source: str | os.PathLike | bytes) -> dict | None:
    """The record a rendering written by intuitf carries (see :func:`render_record`), or None
    when the picture has none (not written by intuitf, or re-saved by a program that drops
    text chunks). A picture that cannot be read raises :class:`ImageError`."""
    info = _open(source).info
    text = info.get(METADATA_KEY)
    if text is None:
        comment = info.get("comment")
        if isinstance(comment, bytes):
            comment = comment.decode("utf-8", "replace")
        if isinstance(comment, str) and comment.startswith(METADATA_KEY + ":"):
            text = comment[len(METADATA_KEY) + 1 :]
    if not isinstance(text, str):
        return None
    try:
        rec = json.loads(text)
    except ValueError:
        return None
    return rec if isinstance(rec, dict) and isinstance(rec.get("camera"), dict) else None


def _write_atomic(p: Path, data: bytes) -> Path:
    from intuitf.fileio import atomic_write_bytes

    return atomic_write_bytes(p, data, error=ImageError)


def _open(source: str | os.PathLike | bytes) -> Image.Image:
    name = "<bytes>" if isinstance(source, bytes) else str(source)
    try:
        img = Image.open(io.BytesIO(source) if isinstance(source, bytes) else source)
        img.load()
        return img
    except FileNotFoundError as exc:
        raise ImageError(f"{name}: no such image file.", "Check the path.") from exc
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as exc:
        raise ImageError(
            f"{name}: cannot read this as an image ({exc}).",
            "Use a PNG or JPEG file.",
        ) from exc


def load_image(source: str | os.PathLike | bytes) -> np.ndarray:
    """Read a picture (path or encoded bytes) as uint8 RGB (H, W, 3).

    Transparency is flattened onto white, as a viewer would show it.
    """
    img = _open(source)
    if img.mode in ("RGBA", "LA", "PA") or (img.mode == "P" and "transparency" in img.info):
        rgba = np.asarray(img.convert("RGBA"), dtype=np.float32) / 255.0
        rgb = rgba[..., :3] * rgba[..., 3:] + (1.0 - rgba[..., 3:])
        return (rgb * 255.0 + 0.5).astype(np.uint8)
    return np.asarray(img.convert("RGB"), dtype=np.uint8).copy()


def load_image_rgba(source: str | os.PathLike | bytes) -> np.ndarray:
    """Read a picture as uint8 RGBA (H, W, 4), straight (not premultiplied) alpha.

    Pictures without transparency come back with alpha 255 everywhere (sketch layers keep it).
    """
    return np.asarray(_open(source).convert("RGBA"), dtype=np.uint8).copy()
