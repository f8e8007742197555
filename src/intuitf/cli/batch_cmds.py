"""``intuitf batch``: one visual standard across a collection of volumes, locally or on Ray."""

from __future__ import annotations

import difflib
import os
import re
import time
from collections.abc import Sequence
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from typer.core import TyperCommand

from intuitf.batch.runner import DEFAULT_MAX_FAILURES, DEFAULT_RAY_TIMEOUT
from intuitf.cli import judge_options as jo
from intuitf.cli import options as vo
from intuitf.cli.spec_flags import flag_errors
from intuitf.errors import IntuitfError

console = Console()

_RAY_ADDRESS = re.compile(r"^(auto|local|(ray|rays)://\S+|[\w.-]+:\d+)$")

HELP = (
    "Give many volumes the look of one REFERENCE (a picture, a TF JSON, or a finished run).\n\n"
    "Each volume gets its own run under DIR/runs/, seeded with the reference TF carried over to "
    "it (histogram materials matched, so bone lands on bone) and searched against the reference "
    "picture.\n\n"
    "Runs go on a local process pool (--workers, default: the number of cores) or on Ray: --ray "
    "alone starts a local Ray instance, --ray ADDRESS (auto, HOST:PORT, ray://HOST:PORT) joins a "
    "cluster; volumes must be on a path every worker sees.\n\n"
    "Run the same command again (or --resume DIR) to continue after a stop: finished volumes are "
    "skipped, the others resumed with no paid call repeated. The summary (DIR/summary.json, "
    "contact_sheet.png, report.html) flags the volumes far from the reference."
)


def _split_ray(volumes: list[str], known: Sequence[str] = ()) -> tuple[list[str], str | None]:
    """Take ``--ray [ADDRESS]`` out of the arguments (Typer has no option with an optional value).

    The command lets unknown options through (for ``--ray ADDRESS``): one left over is an
    error here, with the ``known`` option names closest to it as Click would suggest them.
    """
    out: list[str] = []
    ray: str | None = None
    i = 0
    while i < len(volumes):
        tok = volumes[i]
        if tok == "--ray":
            ray = "local"
            nxt = volumes[i + 1] if i + 1 < len(volumes) else None
            if nxt is not None and _RAY_ADDRESS.match(nxt) and not Path(nxt).exists():
                ray = nxt
                i += 1
        elif tok.startswith("--ray="):
            ray = tok.split("=", 1)[1] or "local"
        elif tok.startswith("-") and not Path(tok).exists():
            name = tok.split("=", 1)[0]
            # A near spelling first ("--ray-timout"), then an option the token begins with
            # ("--ray-address" meant "--ray ADDRESS"), then what Click would suggest.
            close = (
                difflib.get_close_matches(name, known, n=3, cutoff=0.8)
                or [k for k in known if name.startswith(k + "-")]
                or difflib.get_close_matches(name, known, n=3, cutoff=0.6)
            )
            close = ["--ray [ADDRESS]" if k == "--ray" else k for k in close]
            raise IntuitfError(
                f"No such option: {tok}"
                + (f" (Possible options: {', '.join(close)})" if close else ""),
                "See `intuitf batch --help` for the options.",
            )
        else:
            out.append(tok)
        i += 1
    return out, ray


class _BatchCommand(TyperCommand):
    """Takes ``--ray [ADDRESS]`` out of the arguments before Click parses them.

    Click has no option whose value may be left out, so ``--ray`` alone and ``--ray ADDRESS``
    are read here; the documented ``--ray`` option of the command then only shows in --help.
    """

    def parse_args(self, ctx, args: list[str]) -> list[str]:
        if "--help" not in args:
            args, ray = _split_ray_option(list(args))
            ctx.meta["intuitf.ray"] = ray
        return super().parse_args(ctx, args)


def _split_ray_option(args: list[str]) -> tuple[list[str], str | None]:
    """``--ray`` and its optional ADDRESS out of ``args`` (the other tokens untouched)."""
    out: list[str] = []
    ray: str | None = None
    i = 0
    while i < len(args):
        tok = args[i]
        if tok == "--ray":
            ray = "local"
            nxt = args[i + 1] if i + 1 < len(args) else None
            if nxt is not None and _RAY_ADDRESS.match(nxt) and not Path(nxt).exists():
                ray = nxt
                i += 1
        elif tok.startswith("--ray="):
            ray = tok.split("=", 1)[1] or "local"
        else:
            out.append(tok)
        i += 1
    return out, ray


def _camera(azimuth: float | None, elevation: float | None) -> dict:
    """The judging view of every volume (the session's default when neither is given)."""
    if azimuth is None and elevation is None:
        return {}
    from intuitf.render import Camera

    return Camera(azimuth=azimuth or 0.0, elevation=elevation or 0.0).to_dict()


def _progress_callback(progress: Progress, task) -> callable:
    counts = {"done": 0, "flag": 0}

    def update(event: str, item, result) -> None:
        if event == "started":
            progress.console.print(f"[dim]started[/] {escape(item.key)}")
            return
        if event == "retry":
            why = escape(str((result or {}).get("message", ""))[:160])
            progress.console.print(
                f"[yellow]again[/] {escape(item.key)} (try {int(result['retries']) + 1}) — "
                f"{escape(str(result.get('status')))}: {why}"
            )
            return
        counts["done"] += 1
        if result is not None:
            status = result.get("status")
            sim = result.get("similarity")
            extra = f" similarity {sim:.3f}" if isinstance(sim, float) else ""
            colour = "green" if status == "completed" else "yellow"
            if status == "failed":
                colour = "red"
            what = "done before" if event == "skipped" else status
            msg = (
                ""
                if status == "completed"
                else f" — {escape(str(result.get('message', ''))[:160])}"
            )
            progress.console.print(
                f"[{colour}]{escape(str(what))}[/] {escape(item.key)}{extra}"
                f" · {int(result.get('calls') or 0)} calls{msg}"
            )
        progress.update(task, completed=counts["done"])

    return update


def register(app: typer.Typer) -> None:
    @app.command(
        help=HELP,
        context_settings={"ignore_unknown_options": True},
        cls=_BatchCommand,
    )
    def batch(
        ctx: typer.Context,
        reference: str = typer.Argument(
            None,
            metavar="REFERENCE",
            help="A picture, a TF JSON, or a finished run folder. Not needed with --resume.",
            show_default=False,
        ),
        volumes: list[str] = typer.Argument(
            None,
            metavar="VOLUMES...",
            help="Volume files, folders (a DICOM folder: one volume per series) or globs. "
            "Add --ray [ADDRESS] to run on Ray.",
            show_default=False,
        ),
        output: Path = typer.Option(Path("runs/batch"), "-o", "--output", help="Batch folder."),
        resume: Path = typer.Option(
            None, "--resume", help="Continue the batch in this folder, as it was started."
        ),
        text: str = typer.Option(
            None, "--text", help="What you want, in words, beside the picture."
        ),
        about: str = typer.Option(None, "--about", help="What the volumes are, e.g. 'CT scans'."),
        reference_volume: str = typer.Option(
            None,
            "--reference-volume",
            help="The volume a TF JSON reference was designed for (its materials; its picture).",
        ),
        carry: bool = typer.Option(
            True,
            "--carry/--no-carry",
            help="Seed each volume's first population with the reference TF carried over to it.",
        ),
        evaluator: str = typer.Option(
            None,
            "--evaluator",
            help="metric | openai:MODEL | gemini:MODEL | ollama:MODEL | vllm:MODEL | lmstudio:MODEL | openrouter:MODEL | URL",
        ),
        base_url: str = typer.Option(
            None, "--base-url", help="Server URL for an OpenAI-compatible model."
        ),
        budget_usd: float = typer.Option(
            None, "--budget-usd", min=0.0, help="The whole batch's money limit (all workers)."
        ),
        budget_calls: int = typer.Option(
            None, "--budget-calls", min=0, help="The whole batch's model-call limit (all workers)."
        ),
        workers: int = typer.Option(
            None, "--workers", min=1, help="Worker processes (Ray: actors). Default: the cores."
        ),
        per_worker: int = typer.Option(
            4,
            "--per-worker",
            min=1,
            help="Volumes each worker drives at once: their renders take turns, their judge "
            "calls overlap.",
        ),
        max_concurrency: int = typer.Option(
            None,
            "--max-concurrency",
            min=1,
            help="At most this many judge requests in flight, whole batch (a provider's limit).",
        ),
        rate_limit: float = typer.Option(
            None,
            "--rate-limit",
            min=0.001,
            metavar="RPM",
            help="At most this many judge requests per minute, whole batch.",
        ),
        ray_doc: str = typer.Option(
            None,
            "--ray",
            metavar="[ADDRESS]",
            help="Run on Ray: alone, a local Ray instance that goes away with the batch; with "
            "ADDRESS (HOST:PORT as `ray start --head` prints it, ray://HOST:PORT, auto), "
            "join that cluster.",
            show_default=False,
        ),
        max_failures: int = typer.Option(
            DEFAULT_MAX_FAILURES,
            "--max-failures",
            min=0,
            help="Try a volume this many more times when its run fails (its judge down, an "
            "error, its worker lost); each try resumes it.",
        ),
        ray_timeout: float = typer.Option(
            DEFAULT_RAY_TIMEOUT,
            "--ray-timeout",
            min=0.1,
            help="Seconds to wait for the Ray cluster to answer before giving up.",
        ),
        flag_below: float = typer.Option(
            0.5,
            "--flag-below",
            help="Flag volumes whose best has a similarity to the reference below this.",
        ),
        population: int = typer.Option(32, "--population"),
        generations: int = typer.Option(12, "--generations"),
        gaussians: int = typer.Option(5, "--gaussians"),
        seed: int = typer.Option(0, "--seed"),
        explorer: vo.ExplorerOpt = "ga",
        protocol: vo.ProtocolOpt = "efficient",
        size: int = typer.Option(256, "--size", help="Image size for judging."),
        output_size: int = typer.Option(
            512, "--output-size", help="Image size of the best renderings."
        ),
        top: int = typer.Option(4, "--top", help="How many best TFs to keep per volume."),
        shading: bool = typer.Option(True, "--shading/--no-shading"),
        device: str = typer.Option(
            "auto",
            "--device",
            metavar="auto|cpu|cuda",
            help="Where to render: cuda (an NVIDIA GPU), cpu, or auto (the GPU when usable).",
        ),
        palette: bool = typer.Option(True, "--palette/--no-palette"),
        hints: bool = typer.Option(True, "--hints/--no-hints"),
        init: bool = typer.Option(
            False,
            "--init/--no-init",
            help="Spend the first third of the generations on quality alone (as optimize "
            "does). Off by default when a TF is carried: the search starts from the reference.",
        ),
        azimuth: float = typer.Option(None, "--azimuth"),
        elevation: float = typer.Option(None, "--elevation"),
        request_timeout: float = typer.Option(None, "--request-timeout", min=0.001),
        answer_deadline: float = typer.Option(None, "--answer-deadline", min=0.001),
        max_output_tokens: jo.MaxOutputTokensOpt = None,
        reasoning_effort: jo.ReasoningEffortOpt = None,
        price: jo.PriceOpt = None,
        unpriced: jo.UnpricedOpt = False,
        shape: vo.ShapeOpt = None,
        dtype: vo.DtypeOpt = None,
        byte_order: vo.ByteOrderOpt = None,
        spacing: vo.SpacingOpt = None,
        max_dim: vo.MaxDimOpt = None,
    ) -> None:
        from intuitf.batch.job import BatchJob, BatchRequest
        from intuitf.batch.summary import summary_table

        started = time.perf_counter()
        args = ([reference] if reference else []) + list(volumes or [])
        known = [o for p in ctx.command.params for o in p.opts if o.startswith("--")]
        args, ray = _split_ray(args, known)
        ray = ray or ctx.meta.get("intuitf.ray") or ray_doc
        if ray is not None:
            from intuitf.batch.runner import import_ray

            import_ray()  # says how to install it, before anything else happens
        # --max-concurrency is the whole batch's limit (the runner shares it out).
        judge_options = jo.judge_options(None, max_output_tokens, reasoning_effort, price, unpriced)
        if request_timeout is not None:
            judge_options["timeout"] = request_timeout
        if answer_deadline is not None:
            judge_options["deadline"] = answer_deadline
        common = dict(
            budget_calls=budget_calls, budget_usd=budget_usd, workers=workers,
            per_worker=per_worker, ray=ray, max_concurrency=max_concurrency,
            rate_per_min=rate_limit, flag_below=flag_below, judge_options=judge_options,
            max_failures=max_failures, ray_timeout=ray_timeout,
        )  # fmt: skip
        if resume is not None:
            if args:
                raise IntuitfError(
                    "--resume DIR continues a batch as it was started: give no REFERENCE or VOLUMES.",
                    "Drop them, or start a new batch with -o.",
                )
            req = BatchRequest(root=str(resume), evaluator=evaluator, base_url=base_url, **common)
        else:
            if len(args) < 2:
                raise IntuitfError(
                    "Give a REFERENCE and at least one volume (file, folder or glob).",
                    "For example: intuitf batch foot-run/ scans/*.nii.gz -o out",
                )
            settings = dict(
                population=population, generations=generations, n_gaussians=gaussians,
                seed=seed, explorer=str(explorer), protocol=str(protocol), image_size=size,
                output_size=output_size, top_k=top, shading=shading,
                camera=_camera(azimuth, elevation), palette_hint=palette,
                material_hints=hints, device=device,
            )  # fmt: skip
            if carry and not init:
                settings["stages"] = [["customize", generations]]
            req = BatchRequest(
                root=str(output),
                reference=args[0],
                volumes=args[1:],
                text=text,
                about=about,
                evaluator=evaluator or "metric",
                base_url=base_url,
                settings=settings,
                reader=vo.volume_kwargs(shape, dtype, byte_order, spacing, max_dim),
                reference_volume=reference_volume,
                carry=carry,
                **common,
            )
        with flag_errors():
            job = BatchJob(req)
        with job:
            for note in job.reference.notes:
                console.print(f"[yellow]note:[/] {escape(note)}")
            if getattr(job, "lost", 0):
                console.print(
                    f"[yellow]note:[/] {job.lost} model request(s) were under way when the batch "
                    "last stopped; they count as spent."
                )
            ray_used = job.req.ray
            where = (
                f"Ray ({ray_used})"
                if ray_used
                else f"{workers or os.cpu_count()} worker process(es)"
            )
            if job.req.backend_from_record is not None:
                where += " as the batch was started"
            console.print(
                f"Batch of [bold]{len(job.items)}[/] volume(s) after {escape(job.reference.describe())}, "
                f"judge {escape(job.config.template['judge']['spec'])}, on {where}; folder {job.root}"
            )
            with Progress(
                TextColumn("volumes"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                console=console,
            ) as progress:
                task = progress.add_task("volumes", total=len(job.items))
                summary = job.run(on_update=_progress_callback(progress, task))
        console.print(summary_table(summary))
        t = summary["totals"]
        budget = summary.get("budget") or {}
        spent = ""
        if budget:
            spent = (
                f" Budget: {budget['paid_calls']} calls paid"
                + (f" of {budget['max_calls']}" if budget.get("max_calls") is not None else "")
                + f", ${budget['paid_usd']:.4f}"
                + (f" of ${budget['max_usd']:.2f}" if budget.get("max_usd") is not None else "")
                + "."
            )
        console.print(
            f"{t['completed']} of {t['volumes']} completed, {t['flagged']} flagged, "
            f"{t['calls']} model calls, ${t['cost_usd']:.4f}, "
            f"{time.perf_counter() - started:.1f} s.{spent}"
        )
        if t.get("matches"):
            console.print(
                f"{t['undecided']} of {t['matches']} matches "
                f"({100 * t['undecided_share']:.0f} %) stayed undecided."
            )
        console.print(
            f"Summary: [bold]{job.root / 'summary.json'}[/]  report: {job.root / 'report.html'}"
        )
        if t["completed"] < t["volumes"]:
            console.print(
                f"[yellow]Not every volume finished.[/] Continue with: intuitf batch --resume {job.root}"
            )
            raise typer.Exit(3)
