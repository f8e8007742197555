"""Reading and writing pictures (PNG out; PNG, JPEG, ... in) with Pillow."""

from __future__ import annotations

import io
import os
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

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


def png_bytes(image: np.ndarray) -> bytes:
    """The image (uint8, or float in [0, 1]) encoded as PNG."""
    buf = io.BytesIO()
    Image.fromarray(_as_uint8(image)).save(buf, format="PNG")
    return buf.getvalue()


def save_png(image: np.ndarray, path: str | os.PathLike) -> Path:
    """Write ``image`` as a PNG atomically: a crash never leaves half a file at ``path``."""
    p = Path(path)
    data = png_bytes(image)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            os.replace(tmp, p)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError as exc:
        raise ImageError(
            f"{p}: cannot write the image ({exc.strerror or exc}).",
            "Check that the folder exists and is writable, or choose another output path.",
        ) from exc
    return p


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
