"""Small pieces every route module shares: API errors, cameras, image encoding, limits."""

from __future__ import annotations

import base64
import io
import re
from typing import Any

import numpy as np
from fastapi import Request

from intuitf.errors import IntuitfError

#: The largest view the server renders (pixels per side).
MAX_VIEW_SIZE = 1024
MIN_VIEW_SIZE = 16

_CANDIDATE = re.compile(r"^g\d{3,}-\d{3,}$")
_RUN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,120}$")


class ApiError(Exception):
    """An error the page shows: HTTP ``status``, ``detail`` (what happened) and ``hint``."""

    def __init__(self, status: int, detail: str, hint: str | None = None) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail
        self.hint = hint

    def body(self) -> dict[str, Any]:
        out: dict[str, Any] = {"detail": self.detail}
        if self.hint:
            out["hint"] = self.hint
        return out


def user_error(exc: IntuitfError, status: int = 422) -> ApiError:
    """An :class:`IntuitfError` (bad input, a volume that does not load, ...) as an API error."""
    return ApiError(status, exc.message, exc.hint)


def not_found(what: str, hint: str | None = None) -> ApiError:
    return ApiError(404, what, hint)


def check_run_name(name: str) -> str:
    if not _RUN.match(name or ""):
        raise not_found(f"There is no run {name!r}.", "Use a name from the run list.")
    return name


def check_candidate_id(cid: str) -> str:
    if not _CANDIDATE.match(cid or ""):
        raise not_found(f"{cid!r} is not a candidate id.", "Candidate ids look like g003-007.")
    return cid


def parse_qid(qid: str) -> tuple[str, str]:
    """``RUN/gGGG-NNN`` as (run, candidate); 404 for anything else (paths included)."""
    run, sep, cid = (qid or "").partition("/")
    if not sep:
        raise not_found(f"{qid!r} is not a candidate id.", "Write it as RUN/gGGG-NNN.")
    return check_run_name(run), check_candidate_id(cid)


def camera_of(d: Any):
    """A :class:`~intuitf.render.Camera` from the page's JSON (``orthographic`` accepted)."""
    from intuitf.render import Camera

    if d is None:
        return Camera()
    if not isinstance(d, dict):
        raise ApiError(422, "A camera must be a JSON object.", "Send {azimuth, elevation, ...}.")
    d = {k: v for k, v in d.items() if v is not None}
    ortho = d.pop("orthographic", None)
    if ortho is not None:
        d["projection"] = "orthographic" if ortho else "perspective"
    try:
        camera = Camera.from_dict(d)
    except IntuitfError as exc:
        raise user_error(exc) from None
    check_camera(camera)
    return camera


#: Zoom a view may ask for (the page's wheel keeps within 0.25..8).
ZOOM_RANGE = (0.01, 100.0)
#: Pan, in view widths either way.
PAN_LIMIT = 10.0


def check_camera(camera) -> None:
    """422 for a camera no view can show: angles or pan that are not finite or far outside
    the picture, a zoom outside :data:`ZOOM_RANGE`."""
    values = [camera.azimuth, camera.elevation, camera.roll, camera.zoom, camera.fov, *camera.pan]
    if not all(np.isfinite(float(v)) for v in values):
        raise ApiError(422, "A camera's numbers must be finite.", "Send ordinary numbers.")
    lo, hi = ZOOM_RANGE
    if not lo <= camera.zoom <= hi:
        raise ApiError(
            422,
            f"Camera zoom must be within {lo:g}..{hi:g}, got {camera.zoom:g}.",
            "Zoom 1 fits the volume.",
        )
    if any(abs(float(p)) > PAN_LIMIT for p in camera.pan):
        raise ApiError(
            422,
            f"Camera pan must be within ±{PAN_LIMIT:g} view widths.",
            "Pan 0 centres the volume.",
        )


def check_size(size: int) -> int:
    size = int(size)
    if not MIN_VIEW_SIZE <= size <= MAX_VIEW_SIZE:
        raise ApiError(
            422,
            f"A view size must be within {MIN_VIEW_SIZE}..{MAX_VIEW_SIZE} pixels, got {size}.",
            "Ask for a smaller view.",
        )
    return size


def background_of(bg: Any) -> tuple[float, float, float]:
    """``[r, g, b]`` in 0..1 (or 0..255, recognised by a value above 1)."""
    if bg is None:
        return (0.0, 0.0, 0.0)
    try:
        vals = [float(v) for v in bg]
    except (TypeError, ValueError):
        vals = []
    if len(vals) != 3 or not all(np.isfinite(v) and 0 <= v <= 255 for v in vals):
        raise ApiError(422, "A background is three numbers [r, g, b].", "Use values in 0..1.")
    if max(vals) > 1:
        vals = [v / 255.0 for v in vals]
    return (vals[0], vals[1], vals[2])


def tf_of(d: Any):
    """A :class:`~intuitf.tf.GaussianTF` from its JSON form (422 with the reason otherwise)."""
    from intuitf.tf import GaussianTF

    try:
        return GaussianTF.from_dict(d)
    except IntuitfError as exc:
        raise user_error(exc) from None
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise ApiError(
            422,
            f"The transfer function is malformed ({exc}).",
            "Send a TF JSON written by intuitf.",
        ) from None


def render_rgb8(renderer, tf, camera) -> np.ndarray:
    """``renderer.render(tf, camera)`` (kept for the routes that call it: the renderer itself
    composites small pictures with NumPy now, see ``VolumeRenderer.to_rgb8``)."""
    return renderer.render(tf, camera)


def encode_png(image: np.ndarray) -> bytes:
    from intuitf.imageio import png_bytes

    return png_bytes(image)


def encode_jpeg(image: np.ndarray, quality: int = 80) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image[..., :3])).save(buf, format="JPEG", quality=quality)
    return buf.getvalue()


def data_url_png(image: np.ndarray) -> str:
    return "data:image/png;base64," + base64.b64encode(encode_png(image)).decode("ascii")


def mask_overlay(mask: np.ndarray, fill_alpha: int = 80) -> np.ndarray:
    """RGBA: the mask's outline opaque white, its inside faint white, the rest transparent."""
    from scipy.ndimage import binary_erosion

    m = np.asarray(mask, dtype=bool)
    edge = m & ~binary_erosion(m, iterations=1, border_value=0)
    out = np.zeros(m.shape + (4,), dtype=np.uint8)
    out[m] = (255, 255, 255, fill_alpha)
    out[edge] = (255, 255, 255, 255)
    return out


def outline(image: np.ndarray, mask: np.ndarray, colour=(255, 214, 10)) -> np.ndarray:
    """``image`` with the outline of ``mask`` drawn in ``colour`` (the highlighted features)."""
    from scipy.ndimage import binary_dilation

    m = np.asarray(mask, dtype=bool)
    edge = binary_dilation(m, iterations=1) & ~m
    out = np.array(image[..., :3], dtype=np.uint8, copy=True)
    out[edge] = colour
    return out


def state(request: Request):
    """The app's :class:`~intuitf.web.app.WebState`."""
    return request.app.state.web
