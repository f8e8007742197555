"""Pictures the page uploads (a reference, a sketch, a base): decoded with a pixel limit and
re-encoded as PNG on the server, kept in the runs folder, referred to by an opaque id.

Nothing of the uploaded file is kept but its pixels: metadata, odd chunks and anything a
crafted file carries besides the picture are dropped by the re-encoding.
"""

from __future__ import annotations

import io
import re
import secrets
import warnings
from pathlib import Path

import numpy as np

from intuitf.web.common import ApiError

#: The most pixels an uploaded picture may have (decompression bombs are refused unread).
MAX_PIXELS = 4096 * 4096

_ID = re.compile(r"^[0-9a-f]{16}$")


class PictureStore:
    """Uploaded pictures under ``root`` as ``ID.png``."""

    def __init__(self, root: str | Path, max_pixels: int = MAX_PIXELS) -> None:
        self.root = Path(root)
        self.max_pixels = int(max_pixels)

    def save(self, data: bytes) -> dict:
        """Decode, check and re-encode ``data``; ``{id, width, height}`` (blocking)."""
        from PIL import Image, UnidentifiedImageError

        if not data:
            raise ApiError(422, "The picture is empty.", "Upload a PNG or JPEG file.")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error", Image.DecompressionBombWarning)
                img = Image.open(io.BytesIO(data))
                w, h = img.size
                if w * h > self.max_pixels:
                    raise ApiError(
                        413,
                        f"The picture is {w}×{h} pixels, more than the limit of "
                        f"{self.max_pixels:,} pixels.",
                        "Upload a smaller picture (a rendering's size is plenty).",
                    )
                img.load()
        except ApiError:
            raise
        except (
            UnidentifiedImageError,
            OSError,
            ValueError,
            SyntaxError,
            Image.DecompressionBombError,
            Image.DecompressionBombWarning,
        ) as exc:
            raise ApiError(
                422,
                f"The upload cannot be read as a picture ({type(exc).__name__}).",
                "Upload a PNG or JPEG file.",
            ) from None
        has_alpha = img.mode in ("RGBA", "LA", "PA") or (
            img.mode == "P" and "transparency" in img.info
        )
        arr = np.asarray(img.convert("RGBA" if has_alpha else "RGB"), dtype=np.uint8)
        out = io.BytesIO()
        Image.fromarray(arr).save(out, format="PNG")
        pid = secrets.token_hex(8)
        self.root.mkdir(parents=True, exist_ok=True)
        (self.root / f"{pid}.png").write_bytes(out.getvalue())
        return {"id": pid, "width": int(arr.shape[1]), "height": int(arr.shape[0])}

    def path(self, pid: str) -> Path:
        """The stored file of upload ``pid`` (404 for an unknown or malformed id)."""
        p = self.root / f"{pid}.png"
        if not _ID.match(pid or "") or not p.is_file():
            raise ApiError(
                404, f"There is no uploaded picture {str(pid)[:40]!r}.", "Upload the picture again."
            )
        return p

    def size(self, pid: str) -> tuple[int, int]:
        from PIL import Image

        with Image.open(self.path(pid)) as img:
            return img.size
