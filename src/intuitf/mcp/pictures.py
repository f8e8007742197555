"""Pictures for agents: small enough for any MCP client, always with a file beside them.

Desktop clients refuse a tool result over 1 MiB, and count images against the model's context
(about ``width * height / 750`` tokens for Claude models, after scaling the long side to at
most 1568 pixels). A picture therefore goes out as PNG when that is small enough, else as JPEG
at falling quality, and smaller still if needed, so one result stays under
:data:`RESULT_LIMIT`. The full-size picture is written under the output folder as PNG, with
the camera and volume in its metadata, and its path goes into the result's JSON, because some
clients drop image content.
"""

from __future__ import annotations

import base64
import io
import math
from dataclasses import dataclass

import numpy as np
from PIL import Image

#: What one tool result may weigh on the wire (desktop clients refuse 1 MiB).
RESULT_LIMIT = 1024 * 1024
#: Room left for the JSON text (sent twice: as text content and as structured content).
TEXT_ALLOWANCE = 96 * 1024
#: The longest side a picture is sent with by default (about 790 image tokens when square).
DEFAULT_MAX_SIDE = 768
#: Long side and pixel count above which Claude models scale images down anyway.
MODEL_MAX_SIDE = 1568
MODEL_MAX_PIXELS = 1_150_000


@dataclass(frozen=True)
class EncodedPicture:
    """One picture as sent: its bytes, type and size, and its estimated token cost."""

    data: bytes
    mime_type: str
    width: int
    height: int

    @property
    def base64(self) -> str:
        return base64.b64encode(self.data).decode("ascii")

    @property
    def wire_bytes(self) -> int:
        """Bytes of the base64 text that carries it."""
        return 4 * math.ceil(len(self.data) / 3)

    @property
    def tokens(self) -> int:
        return image_tokens(self.width, self.height)

    def info(self) -> dict:
        return {
            "mime_type": self.mime_type,
            "width": self.width,
            "height": self.height,
            "bytes": len(self.data),
            "estimated_tokens": self.tokens,
        }


def image_tokens(width: int, height: int) -> int:
    """Tokens a Claude model counts for an image (its published ``w * h / 750`` rule, after its
    own downscaling of large images)."""
    w, h = float(width), float(height)
    scale = min(1.0, MODEL_MAX_SIDE / max(w, h), math.sqrt(MODEL_MAX_PIXELS / max(w * h, 1.0)))
    return int(math.ceil((w * scale) * (h * scale) / 750.0))


def text_tokens(text: str) -> int:
    """A rough token count of JSON text (about four characters a token)."""
    return int(math.ceil(len(text) / 4.0))


def _resize(img: Image.Image, side: int) -> Image.Image:
    w, h = img.size
    if max(w, h) <= side:
        return img
    k = side / max(w, h)
    return img.resize((max(1, round(w * k)), max(1, round(h * k))), Image.Resampling.LANCZOS)


def _png(img: Image.Image) -> bytes:
    buf = io.BytesIO()
    img.save(buf, format="PNG", optimize=False, compress_level=6)
    return buf.getvalue()


def _jpeg(img: Image.Image, quality: int) -> bytes:
    buf = io.BytesIO()
    img.convert("RGB").save(buf, format="JPEG", quality=quality)
    return buf.getvalue()


def encode(
    image: np.ndarray,
    *,
    fmt: str = "auto",
    max_side: int = DEFAULT_MAX_SIDE,
    max_bytes: int | None = None,
) -> EncodedPicture:
    """``image`` (uint8 RGB or RGBA) as PNG or JPEG under ``max_bytes`` (base64 included).

    ``fmt``: ``png`` or ``jpeg`` asks for that format (a PNG that does not fit becomes JPEG),
    ``auto`` sends PNG when it fits and JPEG otherwise.
    """
    if fmt not in ("auto", "png", "jpeg"):
        raise ValueError(f"picture format must be auto, png or jpeg, got {fmt!r}")
    limit = int(max_bytes if max_bytes is not None else RESULT_LIMIT - TEXT_ALLOWANCE)
    raw_limit = limit * 3 // 4  # base64 makes four bytes of three
    img = Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8))
    side = max(16, int(max_side))
    while True:
        small = _resize(img, side)
        if fmt in ("auto", "png"):
            data = _png(small)
            if len(data) <= raw_limit:
                return EncodedPicture(data, "image/png", *small.size)
        for quality in (90, 80, 70, 60, 50):
            data = _jpeg(small, quality)
            if len(data) <= raw_limit:
                return EncodedPicture(data, "image/jpeg", *small.size)
        if side <= 32:
            raise ValueError("cannot make the picture small enough")
        side = side * 3 // 4


def side_by_side(images: list[np.ndarray], gap: int = 4, fill: int = 40) -> np.ndarray:
    """Pictures of the same height in a row, with a thin gap between them."""
    h = max(im.shape[0] for im in images)
    parts: list[np.ndarray] = []
    for i, im in enumerate(images):
        im = im[..., :3]
        if im.shape[0] < h:
            pad = np.full((h - im.shape[0], im.shape[1], 3), fill, np.uint8)
            im = np.concatenate([im, pad], axis=0)
        if i:
            parts.append(np.full((h, gap, 3), fill, np.uint8))
        parts.append(im.astype(np.uint8))
    return np.concatenate(parts, axis=1)


def outline(image: np.ndarray, mask: np.ndarray, color=(255, 220, 0)) -> np.ndarray:
    """``image`` with the border of ``mask`` drawn over it (a picked feature's outline)."""
    m = mask.astype(bool)
    edge = m & ~(np.roll(m, 1, 0) & np.roll(m, -1, 0) & np.roll(m, 1, 1) & np.roll(m, -1, 1))
    out = image[..., :3].copy()
    out[edge] = color
    return out
