"""Cameras as agents write them: orbit angles (intuitf's own form) or position / focal point /
view-up (the convention of VTK and ParaView, which agents and benchmarks use).

World coordinates are those of :mod:`intuitf.render.camera` and of a ``vtkImageData`` with
origin 0 and the volume's spacing: voxel index × spacing. A VTK camera becomes the
:class:`~intuitf.render.camera.Camera` that looks along the same direction with the same
roll and frames the focal plane the same way (``view_angle``, or ``parallel_scale`` for a
parallel projection); a focal point away from the volume's centre becomes a pan. The Camera
keeps its own eye distance, so perspective foreshortening can differ slightly from VTK's when
the VTK camera stands much nearer or farther than the volume's bounding sphere needs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from intuitf.errors import RenderError
from intuitf.render import Camera

ORBIT_FIELDS = {"azimuth", "elevation", "roll", "zoom", "pan", "fov", "projection"}
VTK_FIELDS = {"position", "focal_point", "view_up", "view_angle", "parallel_scale", "projection"}

#: VTK's default perspective view angle (degrees), also the Camera's default ``fov``.
VTK_VIEW_ANGLE = 30.0


def parse_camera(value: Any, extent: tuple[float, float, float]) -> Camera:
    """A :class:`Camera` from ``None`` (the default view), an orbit dict or a VTK dict.

    ``extent`` is the volume's physical box (x, y, z). Raises :class:`RenderError` with a
    message an agent can act on.
    """
    if value is None:
        return Camera()
    if not isinstance(value, dict):
        raise RenderError(
            f"A camera is a JSON object, got {type(value).__name__}.",
            'Use {"azimuth": 30, "elevation": 20, "zoom": 1} or '
            '{"position": [x, y, z], "focal_point": [x, y, z], "view_up": [0, 0, 1]}.',
        )
    keys = set(value)
    if keys & {"position", "focal_point", "view_up", "view_angle", "parallel_scale"}:
        unknown = keys - VTK_FIELDS
        if unknown:
            raise RenderError(
                f"A position/focal-point camera cannot also have {sorted(unknown)}.",
                f"Use only {sorted(VTK_FIELDS)}, or the orbit form without position.",
            )
        return from_vtk(value, extent)
    unknown = keys - ORBIT_FIELDS
    if unknown:
        raise RenderError(
            f"Unknown camera field(s): {sorted(unknown)}.",
            f"Use {sorted(ORBIT_FIELDS)} or {sorted(VTK_FIELDS)}.",
        )
    cam = Camera.from_dict(value)
    if not 0.01 <= cam.zoom <= 100.0 or max(abs(cam.pan[0]), abs(cam.pan[1])) > 10.0:
        raise RenderError(
            f"Camera zoom {cam.zoom:g} or pan {list(cam.pan)} would leave the volume out of view.",
            "Use zoom 0.01 to 100 (1 fits the volume) and pan within ±10.",
        )
    return cam


def _vector(value: Any, name: str) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        v = np.array([])
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise RenderError(f"Camera {name} must be three finite numbers, got {value!r}.")
    return v


def _number(value: Any, name: str, lo: float, hi: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and lo < v < hi):
        raise RenderError(f"Camera {name} must be a number in ({lo:g}, {hi:g}), got {value!r}.")
    return v


def from_vtk(d: dict, extent: tuple[float, float, float]) -> Camera:
    """The Camera for a VTK-style camera (see the module notes)."""
    projection = d.get("projection", "parallel" if "parallel_scale" in d else "perspective")
    if projection not in ("perspective", "parallel", "orthographic"):
        raise RenderError(f"Camera projection must be perspective or parallel, got {projection!r}.")
    position = _vector(d.get("position"), "position")
    ext = np.asarray(extent, dtype=np.float64)
    center = ext / 2.0
    focal = _vector(d["focal_point"], "focal_point") if "focal_point" in d else center
    up_in = _vector(d.get("view_up", (0.0, 0.0, 1.0)), "view_up")
    to_eye = position - focal
    distance = float(np.linalg.norm(to_eye))
    if distance < 1e-9:
        raise RenderError(
            "The camera position and focal point are the same point.",
            "Put the camera somewhere away from the point it looks at.",
        )
    to_eye /= distance
    fwd = -to_eye
    up_perp = up_in - float(up_in @ fwd) * fwd
    if float(np.linalg.norm(up_perp)) < 1e-6:
        raise RenderError(
            "The camera's view_up is parallel to its direction of view.",
            "Give a view_up across the direction from position to focal point, e.g. [0, 0, 1].",
        )
    up_perp /= np.linalg.norm(up_perp)

    elevation = math.degrees(math.asin(max(-1.0, min(1.0, float(to_eye[2])))))
    if abs(abs(elevation) - 90.0) < 1e-6:
        # Straight down (or up): the azimuth is what makes the picture's up the given view_up,
        # with no roll (the Camera's up there is (-sin a, cos a, 0), negated looking up).
        sign = 1.0 if elevation > 0 else -1.0
        azimuth = math.degrees(math.atan2(-sign * up_perp[0], sign * up_perp[1]))
    else:
        azimuth = math.degrees(math.atan2(float(to_eye[0]), -float(to_eye[1])))
    base = Camera(azimuth=azimuth, elevation=elevation)
    _, right0, up0 = base.basis()
    roll = math.degrees(math.atan2(-float(up_perp @ right0), float(up_perp @ up0)))
    if abs(roll) < 1e-9:
        roll = 0.0
    oriented = Camera(azimuth=azimuth % 360.0, elevation=elevation, roll=roll)
    _, right, up = oriented.basis()

    radius = max(0.5 * float(np.linalg.norm(ext)), 1e-6)
    offset = focal - center
    if projection == "perspective":
        angle = _number(d.get("view_angle", VTK_VIEW_ANGLE), "view_angle", 0.0, 180.0)
        fov = VTK_VIEW_ANGLE
        # The Camera's eye distance at zoom 1 and the half height it shows at the centre.
        eye0 = radius / math.sin(math.radians(fov) / 2.0)
        half_seen = distance * math.tan(math.radians(angle) / 2.0)
        zoom = eye0 * math.tan(math.radians(fov) / 2.0) / half_seen
        kw: dict[str, Any] = {"fov": fov, "projection": "perspective"}
    else:
        half_seen = _number(d.get("parallel_scale"), "parallel_scale", 0.0, math.inf)
        zoom = radius / half_seen
        kw = {"projection": "orthographic"}
    if not 0.01 <= zoom <= 100.0:
        raise RenderError(
            f"This camera frames the volume {zoom:.3g} times as large as a fitted view.",
            "Stand nearer or farther: the volume should be at least partly in the picture.",
        )
    # The centre of the box appears shifted against the focal point's offset, in fractions of
    # the picture's width (2 * half_seen across).
    pan = (
        -float(offset @ right) / (2.0 * half_seen),
        -float(offset @ up) / (2.0 * half_seen),
    )
    if max(abs(pan[0]), abs(pan[1])) > 10.0:
        raise RenderError(
            "The focal point is so far from the volume that it would be out of the picture.",
            f"Look at a point near the volume's centre {[round(float(c), 3) for c in center]}.",
        )
    return Camera(azimuth=azimuth % 360.0, elevation=elevation, roll=roll, zoom=zoom,
                  pan=pan, **kw)  # fmt: skip


def to_vtk(camera: Camera, extent: tuple[float, float, float]) -> dict[str, Any]:
    """The VTK-style form of ``camera`` for a square picture (inverse of :func:`from_vtk`)."""
    frame = camera.frame(extent, 64, 64)
    half = frame.half_height
    if frame.perspective:
        half_seen = frame.distance * half  # world half height at the box centre
    else:
        half_seen = half
    focal = frame.center - 2.0 * half_seen * (
        camera.pan[0] * frame.right + camera.pan[1] * frame.up
    )
    position = focal - frame.forward * frame.distance
    out: dict[str, Any] = {
        "position": [round(float(v), 6) for v in position],
        "focal_point": [round(float(v), 6) for v in focal],
        "view_up": [round(float(v), 6) for v in frame.up],
    }
    if frame.perspective:
        out["view_angle"] = round(frame.vtk_view_angle(), 6)
    else:
        out["parallel_scale"] = round(float(half_seen), 6)
        out["projection"] = "parallel"
    return out


def describe(camera: Camera, extent: tuple[float, float, float]) -> dict[str, Any]:
    """Both forms of a camera, for tool results."""
    return {"orbit": camera.to_dict(), "vtk": to_vtk(camera, extent)}
