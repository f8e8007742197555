"""``intuitf render``: one picture of a volume with a transfer function and a camera."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from intuitf.cli import options as vo
from intuitf.errors import RenderError

_VIEW = "View options"

#: Named backgrounds the --background option accepts besides R,G,B and #rrggbb.
NAMED_COLORS = {
    "black": (0.0, 0.0, 0.0),
    "white": (1.0, 1.0, 1.0),
    "grey": (0.5, 0.5, 0.5),
    "gray": (0.5, 0.5, 0.5),
}


def parse_color(text: str) -> tuple[float, float, float]:
    """A colour from ``black``/``white``/``grey``, ``#rrggbb``, ``R,G,B`` in 0–255 or in [0, 1]."""
    t = text.strip().lower()
    if t in NAMED_COLORS:
        return NAMED_COLORS[t]
    if re.fullmatch(r"#?[0-9a-f]{6}", t):
        h = t.lstrip("#")
        return tuple(int(h[i : i + 2], 16) / 255.0 for i in (0, 2, 4))  # type: ignore[return-value]
    parts = [p for p in re.split(r"[,\s]+", t) if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        vals = []
    if len(vals) == 3 and all(0 <= v <= 255 for v in vals):
        scale = 255.0 if max(vals) > 1 else 1.0
        return tuple(v / scale for v in vals)  # type: ignore[return-value]
    raise RenderError(
        f"--background {text!r} is not a colour.",
        "Use black, white, grey, #rrggbb, or R,G,B (0–255 or 0–1).",
    )


def parse_size(text: str) -> int | tuple[int, int]:
    """``512`` or ``640x480`` (width × height)."""
    m = re.fullmatch(r"\s*(\d+)\s*(?:[x×,]\s*(\d+))?\s*", text)
    if not m:
        raise RenderError(
            f"--size {text!r} is not a picture size.", "Use N for N×N or WxH, e.g. 640x480."
        )
    return int(m[1]) if m[2] is None else (int(m[1]), int(m[2]))


def render_camera(
    volume,
    azimuth: float | None = None,
    elevation: float | None = None,
    roll: float | None = None,
    *,
    zoom: float = 1.0,
    fov: float = 30.0,
    orthographic: bool = False,
):
    """The camera ``intuitf render`` draws from: with no angle given, the volume's default
    judging view (:func:`intuitf.session.building.default_camera`, the same as a run's, so a
    picture to sketch on shows what the run judges); else the angles given, the others at the
    classic defaults. Zoom, field of view and projection apply either way."""
    from intuitf.render import Camera

    if azimuth is None and elevation is None and roll is None:
        from intuitf.session.building import default_camera

        view = Camera.from_dict(default_camera(volume))
    else:
        view = Camera(
            azimuth=vo.DEFAULT_AZIMUTH if azimuth is None else azimuth,
            elevation=vo.DEFAULT_ELEVATION if elevation is None else elevation,
            roll=0.0 if roll is None else roll,
        )
    return Camera(
        azimuth=view.azimuth,
        elevation=view.elevation,
        roll=view.roll,
        zoom=zoom,
        fov=fov,
        projection="orthographic" if orthographic else "perspective",
    )


def render_command(
    volume: vo.VolumeArg,
    output: Annotated[
        Path,
        typer.Option(
            "--output",
            "-o",
            help="Picture to write: .png, or .jpg/.jpeg. The PNG records the camera, size and "
            "volume (for sketching on it).",
            show_default=False,
        ),
    ],
    tf_path: Annotated[
        Path | None,
        typer.Option(
            "--tf",
            metavar="TF.json",
            help="Transfer function (default: one made from the volume's histogram).",
        ),
    ] = None,
    azimuth: Annotated[
        float | None,
        typer.Option(
            help="Turn about the vertical (z) axis, degrees. Without --azimuth, --elevation and "
            "--roll: the view chosen for the volume, the one runs judge from "
            f"(given some: the others default to {vo.DEFAULT_AZIMUTH:g}, "
            f"{vo.DEFAULT_ELEVATION:g} and 0).",
            show_default=False,
            rich_help_panel=_VIEW,
        ),
    ] = None,
    elevation: Annotated[
        float | None,
        typer.Option(
            help="Raise the camera towards +z, degrees.", show_default=False, rich_help_panel=_VIEW
        ),
    ] = None,
    roll: Annotated[
        float | None,
        typer.Option(
            help="Turn the picture clockwise, degrees.", show_default=False, rich_help_panel=_VIEW
        ),
    ] = None,
    zoom: Annotated[
        float,
        typer.Option(help="1 fits the whole volume; 2 is twice as large.", rich_help_panel=_VIEW),
    ] = 1.0,
    fov: Annotated[
        float, typer.Option(help="Perspective view angle, degrees.", rich_help_panel=_VIEW)
    ] = 30.0,
    orthographic: Annotated[
        bool, typer.Option("--orthographic", help="Parallel projection.", rich_help_panel=_VIEW)
    ] = False,
    size: Annotated[
        str, typer.Option(metavar="N|WxH", help="Picture size in pixels.", rich_help_panel=_VIEW)
    ] = "512",
    shading: Annotated[
        bool,
        typer.Option("--shading/--no-shading", help="Gradient lighting.", rich_help_panel=_VIEW),
    ] = True,
    background: Annotated[
        str,
        typer.Option(
            metavar="COLOR", help="black, white, #rrggbb or R,G,B.", rich_help_panel=_VIEW
        ),
    ] = "black",
    sample_distance: Annotated[
        float, typer.Option(help="Ray step in voxels.", rich_help_panel=_VIEW)
    ] = 0.5,
    device: Annotated[
        str,
        typer.Option(
            metavar="auto|cpu|cuda",
            help="Where to render: cuda (an NVIDIA GPU), cpu, or auto (the GPU when usable).",
            rich_help_panel=_VIEW,
        ),
    ] = "auto",
    shape: vo.ShapeOpt = None,
    dtype: vo.DtypeOpt = None,
    byte_order: vo.ByteOrderOpt = None,
    spacing: vo.SpacingOpt = None,
    max_dim: vo.MaxDimOpt = None,
) -> None:
    """Render VOLUME with a transfer function and write a PNG (or JPEG).

    The camera orbits the volume's centre: azimuth 0 / elevation 0 looks from -y towards +y
    with +z up; zoom 1 fits the whole volume.
    """
    from intuitf.imageio import image_format, render_record, save_image
    from intuitf.render import Camera, VolumeRenderer
    from intuitf.render.device import select_device
    from intuitf.tf import default_tf, load_tf

    console = Console(stderr=True)
    image_format(output)  # an unknown suffix is refused before any work
    bg = parse_color(background)
    picture = parse_size(size)
    device = select_device(device)  # a missing GPU is reported before any work
    Camera(zoom=zoom, fov=fov)  # a bad zoom or field of view too
    tf = load_tf(tf_path) if tf_path is not None else None
    vol = vo.open_volume(volume, shape, dtype, byte_order, spacing, max_dim)
    for note in vol.notes:
        console.print(f"[dim]{note}[/]", highlight=False)
    camera = render_camera(vol, azimuth, elevation, roll, zoom=zoom, fov=fov,
                           orthographic=orthographic)  # fmt: skip
    if tf is None:
        tf = default_tf(vol.histogram()[0], vol.value_range)
    renderer = VolumeRenderer(
        vol,
        size=picture,
        shading=shading,
        background=bg,
        sample_distance=sample_distance,
        device=device,
    )
    t = time.perf_counter()
    image = renderer.render(tf, camera)
    took = time.perf_counter() - t
    record = render_record(
        camera,
        (renderer.width, renderer.height),
        vol.name,
        shading=shading,
        background=list(bg),
    )
    path = save_image(image, output, metadata=record)
    console.print(
        f"Wrote {path} ({renderer.width}×{renderer.height}, {len(tf)} Gaussians, "
        f"{took * 1000:.0f} ms).",
        highlight=False,
    )


def register(app: typer.Typer) -> None:
    """Add ``render`` to ``app``."""
    app.command("render")(render_command)
