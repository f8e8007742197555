"""The :class:`Camera`: where the viewer stands, relative to a volume's physical box.

Conventions (world coordinates are voxel index × spacing, so the box through the voxel
centres spans ``[0, (n - 1) * spacing]`` along each axis and anisotropic volumes keep their
proportions):

- The camera looks at the centre of the box (plus ``pan``).
- ``azimuth = 0, elevation = 0``: the camera stands on the -y side of the volume looking
  towards +y, with +z up and +x to the right of the picture. For a CT stored with z running
  towards the head and y towards the back, that is the anatomical front view.
- ``azimuth`` turns the camera about the z axis; positive values move it towards +x
  (azimuth 90 looks from +x towards -x).
- ``elevation`` raises the camera towards +z (elevation 90 looks straight down, with +y up).
- ``roll`` turns the camera about its viewing axis; positive roll turns the picture clockwise.
- ``zoom = 1`` fits the bounding sphere of the box across the picture's shorter side, so the
  whole volume is visible from every direction and its size does not change while rotating.
  ``zoom = 2`` shows it twice as large.
- ``pan = (x, y)`` moves the picture's content right and up by those fractions of the view's
  width and height.
- ``fov`` is the perspective view angle across the picture's shorter side, in degrees.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from intuitf.errors import RenderError

PROJECTIONS = ("perspective", "orthographic")

#: The default view of every front end (degrees): a three-quarter view from the front, a
#: little from above. ``Camera()`` itself looks straight on (0, 0); a run's default judging
#: camera is :func:`intuitf.session.building.default_camera`, built from these.
DEFAULT_AZIMUTH = 30.0
DEFAULT_ELEVATION = 20.0


@dataclass(frozen=True)
class Camera:
    """A view of a volume: orbit angles, roll, zoom, pan, projection (see module docstring)."""

    azimuth: float = 0.0
    elevation: float = 0.0
    roll: float = 0.0
    zoom: float = 1.0
    pan: tuple[float, float] = (0.0, 0.0)
    fov: float = 30.0
    projection: str = "perspective"

    def __post_init__(self) -> None:
        for name in ("azimuth", "elevation", "roll", "zoom", "fov"):
            v = float(getattr(self, name))
            if not math.isfinite(v):
                raise RenderError(f"Camera {name} must be a finite number, got {v!r}.")
            object.__setattr__(self, name, v)
        if self.zoom <= 0:
            raise RenderError(
                f"Camera zoom must be positive, got {self.zoom:g}.",
                "Use 1 to fit the volume, larger values to come closer.",
            )
        if not 1.0 <= self.fov <= 150.0:
            raise RenderError(f"Camera fov must be within [1, 150] degrees, got {self.fov:g}.")
        pan = tuple(float(p) for p in self.pan)
        if len(pan) != 2 or not all(math.isfinite(p) for p in pan):
            raise RenderError(f"Camera pan must be two finite numbers, got {self.pan!r}.")
        object.__setattr__(self, "pan", pan)
        if self.projection not in PROJECTIONS:
            raise RenderError(
                f"Camera projection must be one of {PROJECTIONS}, got {self.projection!r}."
            )

    # -- convenience ----------------------------------------------------------------------
    @property
    def orthographic(self) -> bool:
        return self.projection == "orthographic"

    def orbit(self, d_azimuth: float = 0.0, d_elevation: float = 0.0) -> Camera:
        """The camera turned by the given angles (degrees); elevation is kept within ±90."""
        el = max(-90.0, min(90.0, self.elevation + d_elevation))
        return replace(self, azimuth=(self.azimuth + d_azimuth) % 360.0, elevation=el)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["pan"] = list(self.pan)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Camera:
        if not isinstance(d, dict):
            raise RenderError(f"A camera must be a JSON object, got {type(d).__name__}.")
        known = {"azimuth", "elevation", "roll", "zoom", "pan", "fov", "projection"}
        unknown = set(d) - known
        if unknown:
            raise RenderError(
                f"Unknown camera field(s): {', '.join(sorted(unknown))}.",
                f"Use only {', '.join(sorted(known))}.",
            )
        try:
            kw = dict(d)
            if "pan" in kw:
                kw["pan"] = tuple(kw["pan"])
            return cls(**kw)
        except (TypeError, ValueError) as exc:
            raise RenderError(f"The camera is malformed ({exc}): {d!r}") from exc

    # -- geometry -------------------------------------------------------------------------
    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit vectors (forward, right, up) in world coordinates."""
        a, e, r = (math.radians(v) for v in (self.azimuth, self.elevation, self.roll))
        to_eye = np.array([math.sin(a) * math.cos(e), -math.cos(a) * math.cos(e), math.sin(e)])
        up = np.array([-math.sin(a) * math.sin(e), math.cos(a) * math.sin(e), math.cos(e)])
        fwd = -to_eye
        right = np.cross(fwd, up)
        # Positive roll tilts the camera's up towards its left: the picture turns clockwise.
        up_r = math.cos(r) * up - math.sin(r) * right
        right_r = np.cross(fwd, up_r)
        return fwd, right_r / np.linalg.norm(right_r), up_r / np.linalg.norm(up_r)

    def frame(self, extent: tuple[float, float, float], width: int, height: int) -> ViewFrame:
        """Resolve this camera for a box of physical size ``extent`` (x, y, z) and a picture."""
        ext = np.asarray(extent, dtype=np.float64)
        center = ext / 2.0
        radius = max(0.5 * float(np.linalg.norm(ext)), 1e-6)
        fwd, right, up = self.basis()
        aspect = width / height
        half = math.tan(math.radians(self.fov) / 2.0)
        if self.orthographic:
            short = radius / self.zoom
            distance = 2.0 * radius + 1.0  # eye outside the box; rays start at box entry
        else:
            # The sphere fits the shorter side's view angle exactly at zoom 1.
            distance = radius / math.sin(math.radians(self.fov) / 2.0)
            short = half / self.zoom  # half extent of the image plane at distance 1
        hh, hw = (short, short * aspect) if aspect >= 1 else (short / aspect, short)
        eye = center - fwd * distance
        return ViewFrame(
            eye=eye,
            center=center,
            forward=fwd,
            right=right,
            up=up,
            half_width=hw,
            half_height=hh,
            perspective=not self.orthographic,
            pan=self.pan,
            distance=distance,
            width=int(width),
            height=int(height),
        )


@dataclass(frozen=True)
class ViewFrame:
    """A camera resolved for one box and picture size: everything a ray caster needs.

    For orthographic views ``half_width``/``half_height`` are world lengths at the image
    plane; for perspective views they are tangents of the half view angles.
    """

    eye: np.ndarray
    center: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    half_width: float
    half_height: float
    perspective: bool
    pan: tuple[float, float]
    distance: float
    width: int
    height: int

    def packed(self) -> np.ndarray:
        """The frame as a flat float64 array in the layout the kernels read."""
        return np.array(
            [
                *self.eye,
                *self.forward,
                *self.right,
                *self.up,
                self.half_width,
                self.half_height,
                1.0 if self.perspective else 0.0,
                self.pan[0],
                self.pan[1],
                float(self.width),
                float(self.height),
            ],
            dtype=np.float64,
        )

    def rays(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World origins and unit directions (n, 3) of the rays through the centres of pixels
        (row, col): the rays the kernels cast (``kernels._ray``)."""
        sx = (2.0 * (np.asarray(cols) + 0.5) / self.width - 1.0) - 2.0 * self.pan[0]
        sy = (1.0 - 2.0 * (np.asarray(rows) + 0.5) / self.height) - 2.0 * self.pan[1]
        across = (sx[:, None] * self.half_width * self.right[None]
                  + sy[:, None] * self.half_height * self.up[None])  # fmt: skip
        if self.perspective:
            d = self.forward[None] + across
            o = np.repeat(self.eye[None], len(sx), axis=0)
        else:
            o = self.eye[None] + across
            d = np.repeat(self.forward[None], len(sx), axis=0)
        return o, d / np.linalg.norm(d, axis=1, keepdims=True)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, depth) of world points (n, 3): the pixel whose ray (:meth:`rays`) passes
        through each, as fractional indices (a pixel's centre is a whole number), and its
        distance along the view direction."""
        v = np.asarray(points, dtype=np.float64) - self.eye
        depth = v @ self.forward
        x, y = v @ self.right, v @ self.up
        if self.perspective:
            x, y = x / np.maximum(depth, 1e-9), y / np.maximum(depth, 1e-9)
        col = (x / self.half_width + 1.0 + 2.0 * self.pan[0]) * 0.5 * self.width - 0.5
        row = (1.0 - y / self.half_height - 2.0 * self.pan[1]) * 0.5 * self.height - 0.5
        return row, col, depth

    def vtk_view_angle(self) -> float:
        """VTK's vertical view angle (degrees) for the same perspective picture."""
        return math.degrees(2.0 * math.atan(self.half_height))
