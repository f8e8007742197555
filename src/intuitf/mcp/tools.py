"""The MCP tools: names and arguments an agent can guess, JSON results, pictures as images.

Each tool turns its arguments into one call of :class:`~intuitf.mcp.service.McpService` (or
its :class:`~intuitf.mcp.runs.RunDesk`) and the answer into a ``CallToolResult``: the JSON as
text and as structured content, plus at most one picture as image content (PNG or JPEG, sized
by :mod:`.pictures` so the whole result stays under 1 MiB), whose full-size file path is in the
JSON. Errors a caller can cause come back as tool errors with a message and what to do; nothing
an agent sends can stop the server. API keys are blanked out of every result and message.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Awaitable, Callable
from typing import Annotated, Any, Literal

from mcp.server.mcpserver import MCPServer
from mcp.server.mcpserver.exceptions import ToolError
from mcp.types import CallToolResult, ImageContent, TextContent, ToolAnnotations
from pydantic import Field

from intuitf.errors import IntuitfError
from intuitf.mcp import pictures as pics
from intuitf.mcp.service import McpService, Reply

log = logging.getLogger("intuitf.mcp")

Camera = Annotated[
    dict[str, Any] | None,
    Field(
        description="Camera, either form. Orbit: {azimuth, elevation, roll, zoom, pan: [x, y], "
        "fov, projection} (degrees; zoom 1 fits the volume). VTK/ParaView: {position: [x,y,z], "
        "focal_point: [x,y,z], view_up: [x,y,z], view_angle} or with parallel_scale; world "
        "units are voxel index x spacing. Default: the run's judging camera, else the view "
        "intuitf chooses for the volume (the one a new run would judge from)."
    ),
]
Size = Annotated[int, Field(description="Picture size in pixels per side (16-1024).")]
TF = Annotated[
    dict[str, Any] | list[dict[str, Any]] | str | None,
    Field(
        description="Transfer function as Gaussians over the normalised value range [0, 1]: "
        '{"gaussians": [{"mean": 0.6, "width": 0.03, "height": 0.5, "color": [1, 0.9, 0.8]}]} '
        "(height = opacity per voxel, 1-16 Gaussians); a bare list of Gaussians also works."
    ),
]
RunName = Annotated[str, Field(description="Run name, as start_run or list_runs give it.")]
CandidateId = Annotated[
    str, Field(description="Candidate id RUN/gGGG-NNN, as gallery gives it (e.g. foot/g003-007).")
]
Intent = Annotated[
    str | dict[str, Any] | None,
    Field(
        description="What the picture should show: words (a string), or {kind: 'text'|'image'|"
        "'sketch', text, reference: PATH, sketch: PATH (RGBA strokes), base: PATH (the picture "
        "sketched on), about}. Picture paths must lie under the data or output folders."
    ),
]
Judge = Annotated[
    str | dict[str, Any] | None,
    Field(
        description="Judge: 'metric' (offline), 'openai:MODEL', 'gemini:MODEL', 'ollama:MODEL', "
        "... or an OpenAI-compatible server URL; or {spec, base_url, budget_usd, budget_calls, "
        "options}. Default: the server's --evaluator. API keys come from the environment."
    ),
]

READ = ToolAnnotations(read_only_hint=True, open_world_hint=False)
WRITE = ToolAnnotations(read_only_hint=False, destructive_hint=False, open_world_hint=False)


class Results:
    """Turns replies into ``CallToolResult``s and errors into tool errors."""

    def __init__(self, secrets: list[bytes], picture_side: int = pics.DEFAULT_MAX_SIDE) -> None:
        self.secrets = secrets
        self.picture_side = picture_side

    def scrub(self, text: str) -> str:
        from intuitf.web.security import scrub

        if not self.secrets:
            return text
        return scrub(text.encode("utf-8"), self.secrets).decode("utf-8")

    def result(self, reply: Reply, fmt: str = "auto") -> CallToolResult:
        data = dict(reply.data)
        encoded = []
        if reply.pictures:
            first = reply.pictures[0]
            # What the JSON will weigh, twice (text and structured content), plus margin.
            text_guess = len(json.dumps(data, default=str)) + 400
            budget = min(
                pics.RESULT_LIMIT - pics.TEXT_ALLOWANCE, pics.RESULT_LIMIT - 2 * text_guess - 8192
            )
            enc = pics.encode(first.image, fmt=fmt, max_side=self.picture_side, max_bytes=budget)
            encoded.append(enc)
            data["image"] = {"path": str(first.path), **enc.info(),
                             "full_size": [int(first.image.shape[1]), int(first.image.shape[0])]}  # fmt: skip
        text = self.scrub(json.dumps(data, default=_plain))
        if 2 * len(text) > pics.RESULT_LIMIT - 64 * 1024:  # sent twice: text and structured
            raise ToolError(
                f"The answer would be {2 * len(text) // 1024} KiB, more than a client takes. "
                "What to do: ask for less (a smaller limit, a later since, fewer candidates)."
            )
        content: list[Any] = [TextContent(type="text", text=text)]
        content += [
            ImageContent(type="image", data=e.base64, mime_type=e.mime_type) for e in encoded
        ]
        return CallToolResult(content=content, structured_content=json.loads(text))

    async def run(self, call: Callable[[], Awaitable[Reply] | Reply], fmt: str = "auto"):
        from intuitf.session.live import NotLive

        try:
            reply = call()
            if not isinstance(reply, Reply):
                reply = await reply
            if reply.pictures:  # encoding a picture takes a while: not on the server's loop
                import asyncio

                return await asyncio.to_thread(self.result, reply, fmt)
            return self.result(reply, fmt)
        except ToolError as exc:
            raise ToolError(self.scrub(str(exc))) from None
        except IntuitfError as exc:
            raise ToolError(self.scrub(_message(exc.message, exc.hint))) from None
        except NotLive as exc:
            raise ToolError(f"The run {exc} is not going any more.") from None
        except Exception as exc:  # a bug: say so briefly, keep serving, log it (keys blanked)
            import traceback

            log.error("tool failed: %s", self.scrub(traceback.format_exc()))
            raise ToolError(
                self.scrub(f"Internal error ({type(exc).__name__}): {str(exc)[:300]}")
            ) from None


def _message(message: str, hint: str | None) -> str:
    return f"{message} What to do: {hint}" if hint else message


def _plain(o: Any) -> Any:
    if hasattr(o, "item"):
        return o.item()
    if hasattr(o, "tolist"):
        return o.tolist()
    return str(o)


def forbid_unknown_arguments(server: MCPServer) -> None:
    """Make a misspelt argument an error instead of being ignored (and say so in the schemas,
    with ``additionalProperties: false``)."""
    manager = getattr(server, "_tool_manager", None)
    for tool in manager.list_tools() if manager is not None else []:
        model = tool.fn_metadata.arg_model
        model.model_config["extra"] = "forbid"
        model.model_rebuild(force=True)
        tool.parameters = model.model_json_schema(by_alias=True)


def register(server: MCPServer, svc: McpService, results: Results) -> None:
    """Add every intuitf tool to ``server``."""
    answer = results.run
    desk = svc.runs

    # -- volumes ------------------------------------------------------------------------
    @server.tool(annotations=READ)
    async def list_volumes() -> CallToolResult:
        """List the volume files this server may open (under its --data folders), the built-in
        phantom, and the volumes already open with their ids."""
        return await answer(lambda: _thread(svc.list_volumes))

    @server.tool(annotations=READ)
    async def open_volume(
        path: Annotated[
            str,
            Field(description="Volume file under a data folder (from list_volumes), or 'phantom'."),
        ],
        shape: Annotated[
            list[int] | None,
            Field(description="Raw files: grid size [X, Y, Z] (when the name does not say it)."),
        ] = None,
        dtype: Annotated[
            str | None, Field(description="Raw files: uint8, uint16, int16, float32, ...")
        ] = None,
        byte_order: Annotated[
            Literal["little", "big"] | None, Field(description="Raw files: byte order.")
        ] = None,
        spacing: Annotated[
            list[float] | None, Field(description="Voxel size [x, y, z] (overrides the file's).")
        ] = None,
        max_dim: Annotated[
            int | None,
            Field(description="Downsample to at most this many voxels per axis (faster)."),
        ] = None,
    ) -> CallToolResult:
        """Open a volume and describe it; returns its id for the other tools. Opening the same
        file with the same options again returns the same id."""  # fmt: skip
        options = {"shape": shape, "dtype": dtype, "byte_order": byte_order, "spacing": spacing,
                   "max_dim": max_dim}  # fmt: skip
        return await answer(lambda: _thread(svc.open_volume, path, options))

    @server.tool(annotations=READ)
    async def describe_volume(
        volume: Annotated[str, Field(description="Volume id from open_volume.")],
    ) -> CallToolResult:
        """Shape, spacing, physical extent, value range, a coarse log histogram, the materials
        the histogram shows (normalised mean and width, and the value in data units), and the
        named structures when the intent package knows them."""
        return await answer(lambda: _thread(svc.describe_volume, volume))

    # -- pictures -----------------------------------------------------------------------
    @server.tool(annotations=READ)
    async def render(
        volume: Annotated[
            str | None, Field(description="Volume id (renders its current TF unless tf is given).")
        ] = None,
        candidate: Annotated[
            str | None,
            Field(description="Or a candidate id RUN/gGGG-NNN: renders it on its run's volume."),
        ] = None,
        tf: TF = None,
        camera: Camera = None,
        size: Size = 512,
        shaded: Annotated[
            bool | None, Field(description="Gradient shading (default on, or the run's setting).")
        ] = None,
        background: Annotated[
            list[float] | None, Field(description="Background [r, g, b] in [0, 1].")
        ] = None,
        format: Annotated[
            Literal["auto", "png", "jpeg"], Field(description="Image format sent back.")
        ] = "auto",
    ) -> CallToolResult:
        """Render a volume with a transfer function (or a run's candidate) from a camera. Returns
        the picture as an image, the camera in both forms, and the full-size PNG's path."""  # fmt: skip
        return await answer(
            lambda: svc.render(
                volume_id=volume,
                candidate=candidate,
                tf=tf,
                camera=camera,
                size=size,
                shaded=shaded,
                background=background,
            ),  # fmt: skip
            format,
        )

    # -- transfer functions --------------------------------------------------------------
    @server.tool(annotations=READ)
    async def get_tf(
        volume: Annotated[
            str | None,
            Field(description="Volume id: its current TF (a histogram-aware default at first)."),
        ] = None,
        candidate: Annotated[
            str | None, Field(description="Or a candidate id RUN/gGGG-NNN.")
        ] = None,
    ) -> CallToolResult:
        """Get a transfer function as Gaussians (JSON)."""  # fmt: skip
        return await answer(lambda: _thread(svc.get_tf, volume, candidate))

    @server.tool(annotations=WRITE)
    async def set_tf(
        volume: Annotated[str, Field(description="Volume id.")],
        tf: TF,
    ) -> CallToolResult:
        """Set the volume's current TF (used by render and export when no TF or candidate is
        given, and by start_run with start_from_tf)."""
        return await answer(lambda: _thread(svc.set_tf, volume, tf))

    @server.tool(annotations=WRITE)
    async def edit_gaussian(
        volume: Annotated[str, Field(description="Volume id.")],
        index: Annotated[
            int, Field(description="0-based Gaussian to change; the count adds a new one.")
        ],
        mean: Annotated[
            float | None, Field(description="Centre in [0, 1] (normalised value).")
        ] = None,
        width: Annotated[
            float | None, Field(description="Standard deviation in [0.002, 0.5].")
        ] = None,
        height: Annotated[float | None, Field(description="Opacity per voxel in [0, 1].")] = None,
        color: Annotated[list[float] | None, Field(description="[r, g, b] in [0, 1].")] = None,
        remove: Annotated[bool, Field(description="Remove this Gaussian instead.")] = False,
    ) -> CallToolResult:
        """Change, add or remove one Gaussian of the volume's current TF."""  # fmt: skip
        changes = {"mean": mean, "width": width, "height": height, "color": color, "remove": remove}
        return await answer(lambda: _thread(svc.edit_gaussian, volume, index, changes))

    # -- runs -----------------------------------------------------------------------------
    @server.tool(annotations=WRITE)
    async def start_run(
        volume: Annotated[str, Field(description="Volume id from open_volume.")],
        intent: Intent = None,
        judge: Judge = None,
        budget_usd: Annotated[
            float | None, Field(ge=0, description="Most money the run's model judge may spend.")
        ] = None,
        budget_calls: Annotated[
            int | None, Field(ge=0, description="Most model calls the run may make.")
        ] = None,
        settings: Annotated[
            dict[str, Any] | None,
            Field(
                description="Run settings: population (4-1000, default 32), generations (default 12), n_gaussians, seed, image_size (judged pictures, 32-2048), shading, background, camera (orbit form), stages, explorer."
            ),
        ] = None,
        start_from_tf: Annotated[
            bool, Field(description="Put the volume's current TF into the first population.")
        ] = False,
        name: Annotated[
            str | None, Field(description="Base of the run's name (default: the volume id).")
        ] = None,
    ) -> CallToolResult:
        """Start a search for a transfer function that shows what the intent asks for. Returns
        the run's name at once; the run goes on in the background (follow it with run_status or
        wait_for_generation, see results with gallery)."""  # fmt: skip
        return await answer(
            lambda: desk.start(
                volume_id=volume,
                intent=intent,
                judge=judge,
                budget_usd=budget_usd,
                budget_calls=budget_calls,
                settings=settings,
                start_from_tf=start_from_tf,
                name=name,
            )  # fmt: skip
        )

    @server.tool(annotations=READ)
    async def list_runs() -> CallToolResult:
        """List the runs under --runs: status, generations, cost, volume, intent, parent."""
        return await answer(lambda: _thread(desk.list_runs))

    @server.tool(annotations=READ)
    async def run_status(
        run: RunName,
        since: Annotated[
            int,
            Field(
                ge=0,
                description="Return events after this sequence number (next_since of the last call).",
            ),
        ] = 0,
        limit: Annotated[int, Field(ge=1, le=500, description="Most events to return.")] = 50,
        matches: Annotated[
            bool, Field(description="Include every judged match (winner, the judge's reasons).")
        ] = False,
    ) -> CallToolResult:
        """A run's progress (stage, generation, matches, calls, cost, time left) and its events
        since a sequence number (generations, stages, verdicts, status, its end)."""
        return await answer(lambda: _thread(desk.status, run, since, limit, matches))

    @server.tool(annotations=READ)
    async def wait_for_generation(
        run: RunName,
        timeout_s: Annotated[
            float, Field(ge=0, le=300, description="Longest wait in seconds.")
        ] = 30.0,
        since: Annotated[
            int | None,
            Field(
                description="Wait for a generation ending after this event number (default: now)."
            ),
        ] = None,
        matches: Annotated[
            bool, Field(description="Include every judged match (winner, the judge's reasons).")
        ] = False,
    ) -> CallToolResult:
        """Wait until the run's next generation ends (or the run ends, or the timeout passes);
        returns its status and the events meanwhile. Other tools keep working while it waits."""  # fmt: skip
        return await answer(lambda: desk.wait(run, timeout_s, since, matches))

    @server.tool(annotations=WRITE)
    async def pause_run(run: RunName) -> CallToolResult:
        """Hold a running run before its next match (matches already asked finish)."""
        return await answer(lambda: desk.control(run, "pause"))

    @server.tool(annotations=WRITE)
    async def continue_run(
        run: RunName,
        budget_usd: Annotated[
            float | None, Field(ge=0, description="A new money budget for the whole run.")
        ] = None,
        budget_calls: Annotated[
            int | None, Field(ge=0, description="A new call budget for the whole run.")
        ] = None,
        judge: Annotated[
            str | None, Field(description="Move the run to another judge (spec string).")
        ] = None,
    ) -> CallToolResult:
        """Let a paused run go on, or continue a stopped one (cancelled, out of budget) from its
        last checkpoint; nothing paid for is asked again."""  # fmt: skip
        return await answer(lambda: desk.continue_run(run, budget_usd, budget_calls, judge))

    @server.tool(annotations=WRITE)
    async def cancel_run(run: RunName) -> CallToolResult:
        """Stop a run before its next match; continue_run goes on from there later."""
        return await answer(lambda: desk.control(run, "cancel"))

    @server.tool(annotations=READ)
    async def gallery(
        run: RunName,
        k: Annotated[int, Field(ge=1, le=16, description="How many of the best to show.")] = 4,
        size: Annotated[int, Field(ge=16, le=512, description="Size of each rendering.")] = 192,
        pictures: Annotated[
            bool, Field(description="Send a contact sheet of the renderings.")
        ] = True,
    ) -> CallToolResult:
        """The run's best distinct candidates of its last judged generation: ids, ranks, ratings,
        what the judge said about each (against whom, won, reasons), and a contact sheet."""  # fmt: skip
        return await answer(lambda: desk.gallery(run, k, size, pictures))

    @server.tool(annotations=WRITE)
    async def prefer(
        run: RunName,
        better: Annotated[
            str, Field(description="Candidate id (gGGG-NNN or RUN/gGGG-NNN) that is better.")
        ],
        worse: Annotated[str, Field(description="Candidate id that is worse.")],
        note: Annotated[str, Field(description="Why (kept in the journal).")] = "",
    ) -> CallToolResult:
        """Say one candidate of the current gallery beats another; the ranking and the search
        take it into account."""  # fmt: skip
        b, w = _cid(better), _cid(worse)
        return await answer(lambda: desk.human(run, lambda s: s.prefer(b, w, note)))

    @server.tool(annotations=WRITE)
    async def choose_best(
        run: RunName,
        best: Annotated[str, Field(description="The best candidate's id.")],
        among: Annotated[
            list[str], Field(min_length=2, description="The candidates it was chosen from (ids).")
        ],
        note: Annotated[str, Field(description="Why.")] = "",
    ) -> CallToolResult:
        """Say which candidate is the best of several (e.g. of the gallery)."""  # fmt: skip
        b, a = _cid(best), [_cid(c) for c in among]
        return await answer(lambda: desk.human(run, lambda s: s.choose_best(b, a, note)))

    @server.tool(annotations=WRITE)
    async def undo_verdict(
        run: RunName,
        verdict_id: Annotated[
            int | None, Field(description="Which verdict (default: the last).")
        ] = None,
    ) -> CallToolResult:
        """Take back a verdict given with prefer or choose_best."""  # fmt: skip
        return await answer(lambda: desk.human(run, lambda s: s.undo_verdict(verdict_id)))

    @server.tool(annotations=READ)
    async def features(
        candidate: CandidateId,
        camera: Camera = None,
        size: Annotated[
            int, Field(ge=16, le=512, description="Size of each feature's picture.")
        ] = 160,
        shaded: bool | None = None,
    ) -> CallToolResult:
        """Each Gaussian (feature) of a candidate rendered alone, with its parameters, to select
        features by index."""  # fmt: skip
        return await answer(
            lambda: desk.features(candidate, camera=camera, size=size, shaded=shaded)
        )

    @server.tool(annotations=WRITE)
    async def select_feature(
        candidate: CandidateId,
        x: Annotated[
            int | None,
            Field(description="Pixel column from the left of the candidate's picture at `size`."),
        ] = None,
        y: Annotated[int | None, Field(description="Pixel row from the top.")] = None,
        index: Annotated[
            int | None, Field(description="Or the feature's (Gaussian's) index.")
        ] = None,
        camera: Camera = None,
        size: Size = 512,
        shaded: bool | None = None,
        clear: Annotated[
            bool, Field(description="Clear this candidate's selection first.")
        ] = False,
        whole: Annotated[
            bool,
            Field(
                description="At a pixel, select every feature that makes it (a structure "
                "drawn by several Gaussians), not only the smallest."
            ),
        ] = False,
    ) -> CallToolResult:
        """Select a feature of a candidate: at a pixel, the visible feature with the smallest
        projected area (the paper's rule; whole: all that make the pixel), or by index.
        Selections add up per candidate; refine changes the selected ones. Shows the pick
        outlined and the feature(s) alone; visible_here lists what the pixel holds."""  # fmt: skip
        return await answer(
            lambda: desk.select(
                candidate,
                x=x,
                y=y,
                index=index,
                camera=camera,
                size=size,
                shaded=shaded,
                clear=clear,
                whole=whole,
            )  # fmt: skip
        )

    @server.tool(annotations=WRITE)
    async def refine(
        candidate: CandidateId,
        text: Annotated[
            str, Field(description="How the selected features should change, in words.")
        ],
        selected: Annotated[
            list[int] | None,
            Field(description="Gaussian indices (default: those chosen with select_feature)."),
        ] = None,
        generations: Annotated[
            int | None, Field(ge=1, le=1000, description="Generations of the refinement.")
        ] = None,
        judge: Judge = None,
    ) -> CallToolResult:
        """Start a refinement run from a candidate: only the selected features change, toward
        what the words say; the rest is kept. Returns the new run's name at once."""  # fmt: skip
        return await answer(lambda: desk.refine(candidate, text, selected, generations, judge))

    @server.tool(annotations=WRITE)
    async def new_query(
        run: RunName,
        intent: Intent,
        generations: Annotated[
            int | None, Field(ge=1, le=1000, description="Generations of the new stage.")
        ] = None,
    ) -> CallToolResult:
        """Ask a run something new (words, a reference or a sketch): a new customize stage
        starts after the generation in progress, keeping the run's history. Once applied,
        the reply says how the new words were read on the volume (``understood``)."""  # fmt: skip
        return await answer(lambda: desk.query(run, intent, generations))

    @server.tool(annotations=WRITE)
    async def branch(
        run: RunName,
        generation: Annotated[
            int | None, Field(ge=0, description="Start where the run was after this generation.")
        ] = None,
        candidate: Annotated[
            str | None,
            Field(description="Or start from this candidate (it joins a fresh first population)."),
        ] = None,
        changes: Annotated[
            dict[str, Any] | None,
            Field(description="Changes to the run's spec: intent, judge and/or settings."),
        ] = None,
    ) -> CallToolResult:
        """Start a new run from a generation or a candidate of another, with changes; the
        history keeps the link. Returns the new run's name at once."""  # fmt: skip
        return await answer(lambda: desk.branch(run, generation, candidate, changes))

    # -- exports --------------------------------------------------------------------------
    @server.tool(annotations=WRITE)
    async def export(
        format: Annotated[
            Literal["paraview", "slicer", "vtk", "imagevis3d", "1dt", "json", "png"],
            Field(
                description="paraview (colour-map preset), slicer (.vp), vtk (Python snippet), imagevis3d (.1dt), json (Gaussians), png (a rendering)."
            ),
        ],
        candidate: Annotated[
            str | None, Field(description="Candidate id RUN/gGGG-NNN to export.")
        ] = None,
        volume: Annotated[
            str | None, Field(description="Or a volume id: export its current TF.")
        ] = None,
        path: Annotated[
            str | None,
            Field(
                description="File under the output folder (relative paths are taken there); default: a name from the id."
            ),
        ] = None,
        size: Annotated[int, Field(description="png: picture size.")] = 512,
        camera: Camera = None,
    ) -> CallToolResult:
        """Write a candidate's (or a volume's current) TF for ParaView, 3D Slicer, VTK,
        ImageVis3D, as JSON, or as a PNG rendering, into the output folder; values in the data's
        own units."""  # fmt: skip
        return await answer(
            lambda: svc.export(
                volume_id=volume,
                candidate=candidate,
                fmt=format,
                path=path,
                size=size,
                camera=camera,
            )  # fmt: skip
        )


def _cid(value: str) -> str:
    """A candidate id without its run prefix (the session knows its own run)."""
    return str(value).rsplit("/", 1)[-1]


async def _thread(fn, *args):
    import asyncio

    return await asyncio.to_thread(fn, *args)
