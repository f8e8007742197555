"""How the images of one comparison are laid out for a multimodal model.

By default each image is its own labelled part: the intent's images first (the reference, the
sketch strokes drawn over their base, or the rendering before an edit and, when the Session
gives the selection's pixels, that rendering with the selected features outlined), each after a text part
that states its role, then the two candidates after the text parts "Image 1 ..." and
"Image 2 ...". The alternative layout puts the two candidates side by side in one picture with
their labels drawn above them (a few models compare better within one image).

The labels are the contract between the prompt and whoever reads it (a model, or the fake
server in :mod:`intuitf.testing.fake_mllm`, which finds the candidates by these labels).
"""

from __future__ import annotations

import base64
import hashlib
import io
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Literal

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from intuitf.errors import JudgeError
from intuitf.evaluator.types import Intent

Layout = Literal["parts", "side_by_side"]
ImageFormat = Literal["png", "jpeg"]

#: Text parts that precede each image part; a reader identifies an image by its label's start.
FIRST_LABEL = "Image 1 (first candidate):"
SECOND_LABEL = "Image 2 (second candidate):"
PAIR_LABEL = "Side by side: Image 1 on the left, Image 2 on the right:"
REFERENCE_LABEL = "Reference image (the style the candidates should match):"
SKETCH_LABEL = (
    "Sketch (coloured strokes drawn over the rendering the user started from; "
    "each stroke means 'make this region this colour'):"
)
BEFORE_LABEL = "Before the edit (the rendering the requested change applies to):"
SELECTION_LABEL = (
    "Selection (the same rendering before the edit, with the selected feature outlined in "
    "magenta and everything else dimmed; the change should happen inside the outline):"
)

#: Geometry of the side-by-side composite: a label band above the panels and a gap between them.
BAND = 32
GAP = 16
_BAND_COLOUR = (255, 255, 255)
_GAP_COLOUR = (128, 128, 128)


@dataclass(frozen=True)
class LabelledImage:
    """One image part and the text that says what it is."""

    role: Literal["first", "second", "pair", "reference", "sketch", "before", "selection"]
    label: str
    image: np.ndarray


def _as_rgb(arr: np.ndarray, what: str) -> np.ndarray:
    a = np.asarray(arr)
    if a.ndim != 3 or a.shape[2] not in (3, 4) or a.dtype != np.uint8:
        raise JudgeError(
            f"The {what} is not an RGB image (got shape {a.shape}, dtype {a.dtype}).",
            "Pass uint8 arrays of shape (H, W, 3).",
        )
    return np.ascontiguousarray(a[..., :3])


def encode_image(arr: np.ndarray, fmt: ImageFormat = "png", quality: int = 90) -> tuple[str, bytes]:
    """Encode an RGB image as PNG (lossless) or JPEG; return (MIME type, bytes)."""
    buf = io.BytesIO()
    img = Image.fromarray(_as_rgb(arr, "image"), "RGB")
    if fmt == "jpeg":
        img.save(buf, format="JPEG", quality=quality)
        return "image/jpeg", buf.getvalue()
    # Fast compression: a rendering is sent once, and level 1 is ~4x faster than the default
    # for about 20% more bytes.
    img.save(buf, format="PNG", compress_level=1)
    return "image/png", buf.getvalue()


_URI_CACHE: OrderedDict[tuple, str] = OrderedDict()
_URI_CACHE_SIZE = 128  # a population of renderings plus the intent images
_URI_LOCK = threading.Lock()


def data_uri(arr: np.ndarray, fmt: ImageFormat = "png", quality: int = 90) -> str:
    """An image as a ``data:`` URI for an ``image_url`` content part.

    A tournament shows each rendering in several matches; encoding is the costly part, so
    the last few hundred encodings are remembered by the content of the image.
    """
    a = np.ascontiguousarray(arr)
    key = (
        hashlib.blake2b(a.tobytes(), digest_size=16).digest(),
        a.shape,
        str(a.dtype),
        fmt,
        quality,
    )
    with _URI_LOCK:
        uri = _URI_CACHE.get(key)
        if uri is not None:
            _URI_CACHE.move_to_end(key)
            return uri
    mime, data = encode_image(a, fmt, quality)
    uri = f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"
    with _URI_LOCK:
        _URI_CACHE[key] = uri
        while len(_URI_CACHE) > _URI_CACHE_SIZE:
            _URI_CACHE.popitem(last=False)
    return uri


def decode_data_uri(uri: str) -> np.ndarray:
    """The RGB array inside a ``data:image/...;base64,`` URI (PNG, JPEG, anything PIL reads)."""
    if not uri.startswith("data:") or ";base64," not in uri:
        raise ValueError("not a base64 data URI")
    raw = base64.b64decode(uri.split(";base64,", 1)[1], validate=False)
    with Image.open(io.BytesIO(raw)) as img:
        return np.asarray(img.convert("RGB"))


def _resize_to_height(arr: np.ndarray, h: int) -> np.ndarray:
    if arr.shape[0] == h:
        return arr
    w = max(1, round(arr.shape[1] * h / arr.shape[0]))
    return np.asarray(Image.fromarray(arr).resize((w, h), Image.Resampling.LANCZOS))


def side_by_side(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Both candidates in one picture, labelled "Image 1" and "Image 2" in a band above them.

    Images of different heights are scaled to the smaller height. Panels are separated by a
    grey gap of :data:`GAP` pixels; :func:`split_side_by_side` undoes the composition.
    """
    a, b = _as_rgb(first, "first image"), _as_rgb(second, "second image")
    h = min(a.shape[0], b.shape[0])
    a, b = _resize_to_height(a, h), _resize_to_height(b, h)
    # Equal panel widths keep the split exact; pad the narrower one with the gap colour.
    w = max(a.shape[1], b.shape[1])
    out = np.empty((BAND + h, 2 * w + GAP, 3), np.uint8)
    out[:] = _GAP_COLOUR
    out[:BAND] = _BAND_COLOUR
    out[BAND:, : a.shape[1]] = a
    out[BAND:, w + GAP : w + GAP + b.shape[1]] = b
    img = Image.fromarray(out)
    draw = ImageDraw.Draw(img)
    font = _label_font()
    for i, x0 in enumerate((0, w + GAP)):
        text = f"Image {i + 1}"
        left, top, right, bottom = draw.textbbox((0, 0), text, font=font)
        draw.text(
            (x0 + (w - (right - left)) / 2, (BAND - (bottom - top)) / 2 - top),
            text,
            fill=(0, 0, 0),
            font=font,
        )
    return np.asarray(img)


def split_side_by_side(composite: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two panels of a :func:`side_by_side` composite (label band and gap removed)."""
    a = np.asarray(composite)
    if a.ndim != 3 or a.shape[0] <= BAND or a.shape[1] <= GAP + 1:
        raise ValueError("not a side-by-side composite")
    w = (a.shape[1] - GAP) // 2
    return a[BAND:, :w], a[BAND:, w + GAP : 2 * w + GAP]


_FONT: ImageFont.ImageFont | ImageFont.FreeTypeFont | None = None


def _label_font() -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    global _FONT
    if _FONT is None:
        try:
            _FONT = ImageFont.load_default(size=20)
        except TypeError:  # Pillow without a scalable default font
            _FONT = ImageFont.load_default()
    return _FONT


def sketch_overlay(base: np.ndarray, sketch: np.ndarray) -> np.ndarray:
    """The RGBA stroke layer alpha-blended over the rendering it was drawn on."""
    b = _as_rgb(base, "sketch base").astype(np.float32)
    s = np.asarray(sketch)
    if s.ndim != 3 or s.shape[2] != 4 or s.shape[:2] != b.shape[:2]:
        raise JudgeError(
            f"The sketch must be an RGBA layer of the base's size {b.shape[:2]} (got {s.shape}).",
            "Draw the strokes on a transparent layer as large as the rendering.",
        )
    alpha = s[..., 3:4].astype(np.float32) / 255.0
    out = b * (1.0 - alpha) + s[..., :3].astype(np.float32) * alpha
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


def intent_images(intent: Intent) -> list[LabelledImage]:
    """The images an intent contributes, each with its role stated."""
    if intent.kind == "image":
        if intent.reference is None:
            raise JudgeError(
                "An image intent needs a reference image.", "Give the picture whose style to match."
            )
        return [LabelledImage("reference", REFERENCE_LABEL, _as_rgb(intent.reference, "reference"))]
    if intent.kind == "sketch":
        if intent.sketch is None or intent.base is None:
            raise JudgeError(
                "A sketch intent needs the stroke layer and the rendering it was drawn on.",
                "Give both Intent.sketch (RGBA) and Intent.base (RGB).",
            )
        return [LabelledImage("sketch", SKETCH_LABEL, sketch_overlay(intent.base, intent.sketch))]
    if intent.kind == "edit":
        if intent.base is None:
            raise JudgeError(
                "An edit intent needs the rendering before the edit.", "Give it as Intent.base."
            )
        base = _as_rgb(intent.base, "rendering before the edit")
        parts = [LabelledImage("before", BEFORE_LABEL, base)]
        if intent.selection_mask is not None and np.asarray(intent.selection_mask).any():
            # "Make this gold" needs the model to see which "this": the paper highlights
            # selections to prevent miscommunication.
            from intuitf.intent.selection import outline_selection

            outlined = outline_selection(base, intent.selection_mask)
            parts.append(LabelledImage("selection", SELECTION_LABEL, outlined))
        return parts
    return []


def comparison_images(
    first: np.ndarray, second: np.ndarray, intent: Intent, layout: Layout = "parts"
) -> list[LabelledImage]:
    """All images of one comparison in the order they are sent: intent images, then candidates.

    The intent's pictures are scaled down to the candidates' size (a 12-megapixel reference
    photo would otherwise be tens of megabytes per request, and the model sees it no better).
    """
    longest = max(*np.asarray(first).shape[:2], *np.asarray(second).shape[:2])
    parts = [
        LabelledImage(p.role, p.label, fit_to(p.image, longest)) for p in intent_images(intent)
    ]
    if layout == "side_by_side":
        parts.append(LabelledImage("pair", PAIR_LABEL, side_by_side(first, second)))
    elif layout == "parts":
        parts.append(LabelledImage("first", FIRST_LABEL, _as_rgb(first, "first image")))
        parts.append(LabelledImage("second", SECOND_LABEL, _as_rgb(second, "second image")))
    else:
        raise JudgeError(f"Unknown image layout {layout!r}.", "Use 'parts' or 'side_by_side'.")
    return parts


#: Roles of the intent's pictures (context), as opposed to the candidates.
CONTEXT_ROLES = ("reference", "sketch", "before", "selection")
#: A context picture is sent as PNG when that is this small, or not much larger than as JPEG
#: (flat strokes and outlines compress well losslessly; photographs do not).
PNG_CONTEXT_BYTES = 48_000
PNG_OVER_JPEG = 1.5


def fit_to(arr: np.ndarray, longest: int) -> np.ndarray:
    """``arr`` scaled down (never up) so that its longer side is at most ``longest`` pixels."""
    h, w = arr.shape[:2]
    if max(h, w) <= longest:
        return arr
    scale = longest / max(h, w)
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    return np.asarray(Image.fromarray(arr).resize(size, Image.Resampling.LANCZOS))


def _context_uri(arr: np.ndarray, quality: int) -> str:
    """A context picture: PNG where that is small (lossless strokes and outlines), else JPEG."""
    png = data_uri(arr, "png")
    if len(png) * 3 // 4 <= PNG_CONTEXT_BYTES:
        return png
    jpeg = data_uri(arr, "jpeg", quality)
    return png if len(png) <= PNG_OVER_JPEG * len(jpeg) else jpeg


def content_parts(
    images: list[LabelledImage],
    fmt: ImageFormat = "png",
    quality: int = 90,
    max_bytes: int | None = None,
) -> list[dict]:
    """Chat-completions content parts: a text label then an ``image_url`` part, per image.

    Candidates are encoded as ``fmt``; the intent's pictures as PNG when small, else JPEG.
    With ``max_bytes``, a request whose images would be larger is re-encoded as JPEG of falling
    quality, then at smaller sizes, until it fits (Gemini takes 20 MB of inline data, many
    servers less); :class:`JudgeError` if even the smallest does not.
    """
    attempts: list[tuple[str, int, float]] = [("as given", quality, 1.0)]
    if max_bytes is not None:
        attempts += [("jpeg", 85, 1.0), ("jpeg", 70, 1.0), ("jpeg", 70, 0.75), ("jpeg", 60, 0.5)]
    total = 0
    for mode, q, scale in attempts:
        out: list[dict] = []
        total = 0
        for item in images:
            arr = item.image
            if scale < 1.0:
                arr = fit_to(arr, max(16, round(max(arr.shape[:2]) * scale)))
            if mode == "jpeg":
                uri = data_uri(arr, "jpeg", q)
            elif item.role in CONTEXT_ROLES:
                uri = _context_uri(arr, q)
            else:
                uri = data_uri(arr, fmt, q)
            total += len(uri)
            out.append({"type": "text", "text": item.label})
            out.append({"type": "image_url", "image_url": {"url": uri}})
        if max_bytes is None or total <= max_bytes:
            return out
    raise JudgeError(
        f"The images of one comparison take {total / 1e6:.1f} MB even as small JPEGs, more "
        f"than the request limit of {max_bytes / 1e6:.1f} MB.",  # type: ignore[operator]
        "Judge at a smaller --size, or raise the judge's max_request_mb.",
    )
