"""Which camera and picture size ``optimize`` judges from.

Without a sketch: ``--azimuth`` / ``--elevation``, or (neither given) the session's default
judging camera, the same for every front end (:func:`intuitf.session.building.default_camera`;
the run's spec then names no camera, so the session decides it with the volume in hand).

With ``--sketch S --on BASE``: the strokes mean something only where they were drawn, so the
judging camera is the one BASE was rendered with, read from the record every picture intuitf
writes carries (:func:`intuitf.imageio.read_render_metadata`), and its size is BASE's unless
``--size`` says otherwise. A BASE without that record needs the camera from the user.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from intuitf.errors import IntuitfError

#: Judging picture size when nothing else decides it.
DEFAULT_SIZE = 256


@dataclass
class JudgingView:
    """The judging camera (``Camera.to_dict()``), picture size, and notes for the user.

    ``default``: nothing chose the camera (no angle, no sketch), so the run leaves it to the
    session (:func:`intuitf.session.building.default_camera`, which may choose per volume);
    ``camera`` is then today's default view.
    """

    camera: dict
    size: int
    notes: list[str] = field(default_factory=list)
    default: bool = False


def default_camera(azimuth: float | None = None, elevation: float | None = None) -> dict:
    """The session's default view, with the angles given here in its place."""
    from intuitf.render import Camera
    from intuitf.session.building import default_camera as session_default

    cam = Camera.from_dict(session_default())
    return Camera.from_dict(
        {
            **cam.to_dict(),
            "azimuth": cam.azimuth if azimuth is None else azimuth,
            "elevation": cam.elevation if elevation is None else elevation,
        }
    ).to_dict()


def _same_angle(a: float, b: float) -> bool:
    return math.isclose((a - b + 180.0) % 360.0 - 180.0, 0.0, abs_tol=1e-6)


def judging_view(
    sketch: Path | None,
    on: Path | None,
    azimuth: float | None,
    elevation: float | None,
    size: int | None,
    volume_name: str | None = None,
) -> JudgingView:
    """The camera and size to judge from (see the module notes); IntuitfError when a sketch's
    base picture cannot say where its strokes are."""
    if sketch is None or on is None:
        chosen = azimuth is None and elevation is None
        return JudgingView(default_camera(azimuth, elevation), size or DEFAULT_SIZE, default=chosen)

    from intuitf.imageio import load_image, read_render_metadata
    from intuitf.render import Camera

    record = read_render_metadata(on)
    height, width = load_image(on).shape[:2]
    notes: list[str] = []
    if record is None:
        if azimuth is None and elevation is None:
            raise IntuitfError(
                f"{on} does not record the camera it was rendered with (it was not written by "
                "intuitf, or a program that saved it dropped its metadata), so it is unknown "
                "which parts of the volume the strokes were drawn on.",
                "Give the view it shows: --azimuth A --elevation E, or make the base picture "
                "with `intuitf render` (it records its camera: with no angle given, the view "
                "chosen for the volume, the one runs judge from) and draw on that.",
            )
        camera = default_camera(azimuth, elevation)
        notes.append(
            f"{on} carries no camera record; judging from azimuth {camera['azimuth']:g}, "
            f"elevation {camera['elevation']:g} as given (other camera settings at their "
            "defaults)."
        )
    else:
        camera = Camera.from_dict(record["camera"]).to_dict()
        given = [
            (flag, value, camera[key])
            for flag, key, value in (
                ("--azimuth", "azimuth", azimuth),
                ("--elevation", "elevation", elevation),
            )
            if value is not None and not _same_angle(value, camera[key])
        ]
        if given:
            said = ", ".join(f"{flag} {value:g}" for flag, value, _ in given)
            raise IntuitfError(
                f"{on} was rendered from azimuth {camera['azimuth']:g}, elevation "
                f"{camera['elevation']:g}, but {said} asks for another view: the strokes would "
                "fall on other structures than the ones they were drawn on.",
                "Leave out --azimuth/--elevation (the picture's own camera is used), or render "
                "a new base picture from the view you want and draw on that.",
            )
        rec_size = record.get("size")
        if (
            isinstance(rec_size, list)
            and len(rec_size) == 2
            and rec_size[0] * height != rec_size[1] * width
        ):
            raise IntuitfError(
                f"{on} is {width}x{height} pixels but was rendered at {rec_size[0]}x"
                f"{rec_size[1]}: it was cropped or stretched since, so its camera no longer "
                "matches it.",
                "Draw on the picture as intuitf wrote it.",
            )
        rec_volume = record.get("volume")
        if volume_name and rec_volume and rec_volume != volume_name:
            notes.append(
                f"{on} was rendered from the volume '{rec_volume}', not '{volume_name}'; "
                "judging from its camera all the same."
            )
    if width != height:
        raise IntuitfError(
            f"{on} is {width}x{height} pixels; runs judge square pictures, so strokes on a "
            "picture of another shape cannot be placed.",
            "Render the base picture square, e.g. `intuitf render VOLUME -o base.png --size "
            f"{DEFAULT_SIZE}`, and draw on that.",
        )
    return JudgingView(camera, size or width, notes)
