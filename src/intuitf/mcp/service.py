"""What the MCP tools do, over the same services as the CLI and the web app.

:class:`McpService` holds the roots, the open volumes (:mod:`.volumes`), the run store
(:class:`~intuitf.session.RunStore`) and the registry of live runs the web app uses
(:class:`~intuitf.session.live.RunRegistry`: each run's Session on its own thread and event loop,
so that no run ever holds up the server). The tools in :mod:`.tools` only turn arguments into
calls here and results into MCP content. Pictures, transfer functions and exports are here;
runs are in :mod:`.runs`.
"""

from __future__ import annotations

import asyncio
import re
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from intuitf.errors import IntuitfError, RenderError, SessionError, TransferFunctionError
from intuitf.mcp.camera import describe as describe_camera
from intuitf.mcp.camera import parse_camera
from intuitf.mcp.roots import Roots
from intuitf.mcp.runs import RunDesk
from intuitf.mcp.volumes import OpenVolume, VolumeShelf
from intuitf.session.scheduler import INTERACTIVE, render_scheduler
from intuitf.tf import GaussianTF

#: Sizes a picture may be rendered at (pixels per side).
MIN_SIZE, MAX_SIZE = 16, 1024
#: What export_tf writes, and the file suffix each gets when the path has none.
EXPORT_SUFFIXES = {
    "paraview": ".paraview.json",
    "slicer": ".vp",
    "vtk": ".vtk.py",
    "imagevis3d": ".1dt",
    "json": ".tf.json",
    "png": ".png",
}
_QID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,120}/g\d{3,}-\d{3,}$")


@dataclass
class Picture:
    """A rendering for a result: the array, what it shows, and where its file went."""

    image: np.ndarray
    path: Path
    caption: str = ""


@dataclass
class Reply:
    """A tool's answer: JSON data and any pictures."""

    data: dict[str, Any]
    pictures: list[Picture] = field(default_factory=list)


@dataclass
class McpConfig:
    """What ``intuitf mcp`` was started with."""

    roots: Roots
    evaluator: str = "metric"
    budget_usd: float | None = None
    budget_calls: int | None = None
    max_live: int = 2
    max_dim: int | None = None
    device: str = "auto"
    picture_side: int = 768


class McpService:
    """The state behind the tools (see the module notes)."""

    def __init__(self, config: McpConfig) -> None:
        from intuitf.session import RunStore
        from intuitf.session.live import RunRegistry

        self.config = config
        self.roots = config.roots
        self.shelf = VolumeShelf(config.roots, max_dim=config.max_dim, device=config.device)
        self.store = RunStore(config.roots.runs)
        self.registry = RunRegistry(max_live=config.max_live)
        self.runs = RunDesk(self)
        self._picture_counter = 0

    def warm_up(self) -> None:
        """Import what a first run and a first picture need, on a background thread, so the
        agent's first start_run and render do not wait for it (seconds on a loaded machine)."""
        import threading

        def work() -> None:
            import importlib

            for name in ("intuitf.explorer.factory", "intuitf.evaluator.metric",
                         "intuitf.evaluator.tournament", "intuitf.render", "intuitf.plots",
                         "intuitf.intent.hints", "intuitf.session.outputs"):  # fmt: skip
                try:
                    importlib.import_module(name)
                except Exception:  # a missing optional part shows when it is used
                    pass

        threading.Thread(target=work, name="intuitf-mcp-warm-up", daemon=True).start()

    async def close(self) -> None:
        """Stop every live run between matches and wait for each to release its folder."""
        await self.registry.close_all()

    # -- volumes --------------------------------------------------------------------------
    def list_volumes(self) -> Reply:
        files = self.shelf.files()
        opened = [
            {"id": ov.id, "source": ov.spec.source, "reader_options": ov.spec.reader_options()}
            for ov in self.shelf.opened()
        ]
        return Reply(
            {
                "files": files,
                "builtin": [{"path": "phantom", "name": "phantom", "shape_xyz": [96, 96, 96]}],
                "open": opened,
                "roots": self.roots.to_dict(),
            }
        )

    def open_volume(self, path: str, options: dict[str, Any]) -> Reply:
        ov = self.shelf.open(path, **options)
        return Reply(self.shelf.describe(ov))

    def describe_volume(self, volume_id: str) -> Reply:
        return Reply(self.shelf.describe(self.shelf.get(volume_id)))

    # -- transfer functions ---------------------------------------------------------------
    def get_tf(self, volume_id: str | None, candidate: str | None) -> Reply:
        if candidate:
            info = self.candidate(candidate)
            return Reply({"candidate": info.qid, "tf": info.tf.to_dict(), "rating": info.rating,
                          "rank": info.rank, "generation": info.generation})  # fmt: skip
        ov = self.shelf.get(volume_id)
        tf = self.shelf.current_tf(ov)
        return Reply({"volume": ov.id, "tf": tf.to_dict(), "gaussians": len(tf)})

    def set_tf(self, volume_id: str, tf: Any) -> Reply:
        ov = self.shelf.get(volume_id)
        new = parse_tf(tf)
        vol = self.shelf.volume(ov)
        if new.value_range is None:
            new = replace(new, value_range=vol.value_range)
        ov.tf = new
        return Reply({"volume": ov.id, "tf": new.to_dict(), "gaussians": len(new)})

    def edit_gaussian(self, volume_id: str, index: int, changes: dict[str, Any]) -> Reply:
        from intuitf.tf.gaussian import Gaussian

        ov = self.shelf.get(volume_id)
        tf = self.shelf.current_tf(ov)
        n = len(tf)
        if changes.pop("remove", False):
            if not 0 <= index < n:
                raise TransferFunctionError(
                    f"The TF has Gaussians 0 to {n - 1}; there is no {index}."
                )
            if n == 1:
                raise TransferFunctionError("A TF keeps at least one Gaussian.")
            gs = [g for i, g in enumerate(tf.gaussians) if i != index]
        elif index == n:  # one past the end: a new Gaussian
            missing = [k for k in ("mean", "width", "height", "color") if changes.get(k) is None]
            if missing:
                raise TransferFunctionError(
                    f"A new Gaussian needs {', '.join(missing)}.",
                    "Give mean, width, height (in [0, 1]) and color [r, g, b].",
                )
            gs = [
                *tf.gaussians,
                Gaussian(**{k: changes[k] for k in ("mean", "width", "height", "color")}),
            ]
        elif 0 <= index < n:
            g = tf.gaussians[index].to_dict()
            g.update({k: v for k, v in changes.items() if v is not None})
            gs = list(tf.gaussians)
            gs[index] = Gaussian.from_dict(g)
        else:
            raise TransferFunctionError(
                f"The TF has Gaussians 0 to {n - 1}; there is no {index}.",
                f"Edit one of 0..{n - 1}, or give index {n} to add one.",
            )
        ov.tf = tf.with_gaussians(gs)
        return Reply({"volume": ov.id, "tf": ov.tf.to_dict(), "gaussians": len(ov.tf)})

    # -- candidates -----------------------------------------------------------------------
    def candidate(self, qid: Any):
        """A run's candidate by its run-qualified id (``RUN/gGGG-NNN``)."""
        if not isinstance(qid, str) or not _QID.match(qid):
            raise SessionError(
                f"{str(qid)[:80]!r} is not a candidate id.",
                "Candidate ids look like foot/g003-007 (run name / candidate), as gallery gives them.",
            )
        self.runs.check_run(qid.split("/", 1)[0])
        return self.store.candidate(qid)

    def candidate_volume(self, info) -> tuple[OpenVolume, dict]:
        """The open volume of a candidate's run, and the run's settings."""
        ov, settings = self.runs.volume_of(info.run)
        return ov, settings

    # -- pictures -------------------------------------------------------------------------
    def _target(self, volume_id, candidate, tf):
        """(open volume, TF, run settings or {}) of what a picture tool is asked to show."""
        if candidate:
            if tf is not None:
                raise TransferFunctionError("Give a candidate or a TF, not both.")
            info = self.candidate(candidate)
            ov, settings = self.candidate_volume(info)
            vol = self.shelf.volume(ov)
            return ov, replace(info.tf, value_range=vol.value_range), settings, info.qid
        if volume_id is None:
            raise SessionError(
                "Say what to show: a volume id (with its current TF, or a TF) or a candidate id."
            )
        ov = self.shelf.get(volume_id)
        t = parse_tf(tf) if tf is not None else self.shelf.current_tf(ov)
        return ov, t, {}, None

    async def render(
        self,
        *,
        volume_id: str | None,
        candidate: str | None,
        tf: Any,
        camera: Any,
        size: int,
        shaded: bool | None,
        background: Any,
    ) -> Reply:
        ov, t, settings, qid = await asyncio.to_thread(self._target, volume_id, candidate, tf)
        vol = await asyncio.to_thread(self.shelf.volume, ov)
        size = check_size(size)
        cam = self._camera(camera, settings, vol)
        shaded = bool(settings.get("shading", True)) if shaded is None else bool(shaded)
        bg = check_background(background, settings)
        vr = await asyncio.to_thread(self.shelf.view_renderer, ov, bg)
        t0 = time.perf_counter()
        image = await render_scheduler().run(lambda: vr.view(t, cam, size, shaded), INTERACTIVE)
        seconds = time.perf_counter() - t0
        path = await asyncio.to_thread(
            self.save_picture, image, f"{qid.replace('/', '-') if qid else ov.id}-render",
            cam, vol, shaded, bg,
        )  # fmt: skip
        data = {
            "volume": ov.id,
            "candidate": qid,
            "camera": describe_camera(cam, vol.extent),
            "size": size,
            "shaded": shaded,
            "background": list(bg),
            "gaussians": len(t),
            "render_seconds": round(seconds, 3),
            "path": str(path),
        }
        return Reply(data, [Picture(image, path)])

    def _camera(self, camera: Any, settings: dict, vol):
        """The camera an agent gave, else the run's judging camera, else the view a new run
        of this volume would judge from (the same default as every other front end)."""
        from intuitf.render import Camera

        if camera is None and settings.get("camera"):
            return Camera.from_dict(settings["camera"])
        if camera is None:
            from intuitf.session.building import default_camera

            return Camera.from_dict(default_camera(vol))
        return parse_camera(camera, vol.extent)

    def save_picture(self, image: np.ndarray, stem: str, camera, vol, shaded: bool, bg) -> Path:
        """Write ``image`` full size under ``OUT/pictures`` with its render record."""
        from intuitf.imageio import render_record, save_png

        self._picture_counter += 1
        stamp = time.strftime("%H%M%S")
        safe = re.sub(r"[^A-Za-z0-9._-]+", "-", stem)[:80]
        path = self.roots.out / "pictures" / f"{stamp}-{self._picture_counter:04d}-{safe}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        record = render_record(camera, (image.shape[1], image.shape[0]), vol.name,
                               shading=shaded, background=list(bg))  # fmt: skip
        return save_png(image, path, record)

    # -- exports --------------------------------------------------------------------------
    async def export(
        self,
        *,
        volume_id: str | None,
        candidate: str | None,
        fmt: str,
        path: str | None,
        size: int,
        camera: Any,
    ) -> Reply:
        fmt = (fmt or "").lower().strip()
        if fmt == "1dt":
            fmt = "imagevis3d"
        if fmt not in EXPORT_SUFFIXES:
            raise TransferFunctionError(
                f"Unknown export format {fmt!r}.", f"Choose one of: {', '.join(EXPORT_SUFFIXES)}."
            )
        ov, t, settings, qid = await asyncio.to_thread(self._target, volume_id, candidate, None)
        vol = await asyncio.to_thread(self.shelf.volume, ov)
        stem = (qid or ov.id).replace("/", "-")
        target = path or f"{stem}{EXPORT_SUFFIXES[fmt]}"
        out = self.roots.writable(target, "export file")
        if not out.suffix:  # a bare name gets the format's suffix
            out = self.roots.writable(out.with_name(out.name + EXPORT_SUFFIXES[fmt]))
        t = replace(t.unfreeze(), value_range=vol.value_range, name=t.name or stem)
        unit = min(vol.spacing)  # heights are opacity per voxel
        data: dict[str, Any] = {"format": fmt, "candidate": qid, "volume": ov.id}
        pictures: list[Picture] = []
        if fmt == "png":
            size = check_size(size)
            cam = self._camera(camera, settings, vol)
            shaded = bool(settings.get("shading", True))
            bg = check_background(None, settings)
            vr = await asyncio.to_thread(self.shelf.view_renderer, ov, bg)
            image = await render_scheduler().run(lambda: vr.view(t, cam, size, shaded), INTERACTIVE)
            from intuitf.imageio import render_record, save_png

            if out.suffix.lower() != ".png":
                out = out.with_name(out.name + ".png")
            record = render_record(cam, size, vol.name, shading=shaded, background=list(bg))
            await asyncio.to_thread(save_png, image, out, record)
            data["camera"] = describe_camera(cam, vol.extent)
            pictures.append(Picture(image, out))
        elif fmt == "json":
            from intuitf.fileio import atomic_write_text

            await asyncio.to_thread(
                atomic_write_text, out, t.to_json(), error=TransferFunctionError
            )
        else:
            from intuitf.tf.export_io import write_export

            name = "1dt" if fmt == "imagevis3d" else fmt
            await asyncio.to_thread(write_export, t, name, out, vol.value_range, unit_distance=unit)
        data.update(
            path=str(out),
            bytes=out.stat().st_size,
            value_range=list(vol.value_range),
            unit_distance=unit,
            how_to_use=_USE[fmt],
        )
        return Reply(data, pictures)


_USE = {
    "paraview": "ParaView: Color Map Editor > Import Presets; set the volume's Scalar Opacity "
    "Unit Distance to unit_distance.",
    "slicer": "3D Slicer: load the .vp file as a volume property (Volume Rendering module).",
    "vtk": "VTK: runpy.run_path(path)['volume_property'] is a vtkVolumeProperty.",
    "imagevis3d": "ImageVis3D: load the .1dt file as a 1D transfer function.",
    "json": "intuitf: GaussianTF.from_json, or intuitf render --tf.",
    "png": "The picture itself (its PNG text holds the camera and volume).",
}


def parse_tf(value: Any) -> GaussianTF:
    """A TF from its JSON form (a dict with ``gaussians``, a JSON string, or a list of
    Gaussians)."""
    import json

    if isinstance(value, str):
        try:
            value = json.loads(value)
        except ValueError as exc:
            raise TransferFunctionError(f"The TF is not valid JSON: {exc}.") from None
    if isinstance(value, list):
        value = {"gaussians": value}
    if isinstance(value, dict):  # an agent need not write the file format's marker
        from intuitf.tf.gaussian import TF_FORMAT, TF_VERSION

        value = {"format": TF_FORMAT, "version": TF_VERSION, **value}
    if not isinstance(value, dict):
        raise TransferFunctionError(
            f"A TF is a JSON object with 'gaussians', got {type(value).__name__}.",
            'Write {"gaussians": [{"mean": 0.5, "width": 0.05, "height": 0.4, '
            '"color": [1, 0.9, 0.8]}]}.',
        )
    try:
        return GaussianTF.from_dict(value)
    except TransferFunctionError:
        raise
    except (KeyError, TypeError, ValueError) as exc:
        raise TransferFunctionError(f"The TF is malformed: {exc!r}.") from None


def check_size(size: Any) -> int:
    try:
        s = int(size)
    except (TypeError, ValueError):
        s = -1
    if not MIN_SIZE <= s <= MAX_SIZE:
        raise RenderError(
            f"A picture is {MIN_SIZE} to {MAX_SIZE} pixels a side, got {size!r}.",
            "Ask for 256 or 512; pictures sent back are scaled down for the client anyway.",
        )
    return s


def check_background(value: Any, settings: dict) -> tuple[float, float, float]:
    if value is None:
        value = settings.get("background", (0.0, 0.0, 0.0))
    try:
        bg = tuple(float(c) for c in value)
    except (TypeError, ValueError):
        bg = ()
    if len(bg) != 3 or not all(0.0 <= c <= 1.0 for c in bg):
        raise RenderError(
            f"A background is three numbers in [0, 1] (red, green, blue), got {value!r}."
        )
    return (bg[0], bg[1], bg[2])


__all__ = ["IntuitfError", "McpConfig", "McpService", "Picture", "Reply"]
