"""``intuitf optimize`` (the main job) and ``intuitf demo`` (the main job on built-in inputs)."""

from __future__ import annotations

import time
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

from intuitf.cli import judge_options as jo
from intuitf.cli import options as vo
from intuitf.cli.spec_flags import flag_errors
from intuitf.cli.views import default_camera, judging_view
from intuitf.errors import IntuitfError
from intuitf.tf import load_tf

console = Console()

DEMO_TEXT = "opaque ivory bone, faint red skin"
DEMO_ABOUT = "a CT-like phantom of a human head"


def _intent_spec(text, image, sketch, on, about) -> dict:
    """The intent of the command line, as spec data (pictures by path)."""
    if sketch is not None:
        if on is None:
            raise IntuitfError(
                "--sketch needs --on BASE.png: the rendering the strokes were drawn on."
            )
        return {"kind": "sketch", "text": text, "sketch": str(sketch), "base": str(on),
                "about": about}  # fmt: skip
    if image is not None:
        return {"kind": "image", "text": text, "reference": str(image), "about": about}
    if text:
        return {"kind": "text", "text": text, "about": about}
    return {"kind": "none", "about": about}


def _judge_spec(evaluator, base_url, budget_usd, budget_calls, timeouts, judged=None) -> dict:
    options = dict(judged or {})
    if timeouts.get("request_timeout") is not None:
        options["timeout"] = timeouts["request_timeout"]
    if timeouts.get("answer_deadline") is not None:
        options["deadline"] = timeouts["answer_deadline"]
    return {"spec": evaluator or "metric", "base_url": base_url, "budget_usd": budget_usd,
            "budget_calls": budget_calls, "options": options}  # fmt: skip


def _timeout_options(timeouts: dict) -> dict:
    return _judge_spec(None, None, None, None, timeouts)["options"]


class _ProgressView:
    """Rich progress from the session's events: generation, matches, calls, cost, time left."""

    def __init__(self, progress: Progress, session) -> None:
        self.progress = progress
        self.session = session
        self.task = progress.add_task("starting", total=session.total_generations,
                                      completed=session.generation)  # fmt: skip
        self.matches = 0
        self.what = "starting"

    def __call__(self, e) -> None:
        s = self.session
        d = e.data
        if e.type == "generation_started":
            self.matches, self.what = 0, "rendering"
        elif e.type == "rendered":
            self.what = "judging"
        elif e.type == "match_judged":
            self.matches += 1
            self.what = f"{self.matches} matches"
        elif e.type == "generation_ended":
            self.what = "done"
        elif e.type == "run_ended":
            self.what = "finished"
        else:
            return
        left = ""
        if s.generation_seconds:
            per = sum(s.generation_seconds) / len(s.generation_seconds)
            left = f" · ~{(s.total_generations - s.generation) * per:.0f}s left"
        generation = d.get("generation", s.generation)
        cost = s.cost
        desc = (
            f"gen {min(generation + 1, s.total_generations)}/{s.total_generations} [{s.stage}] "
            f"{self.what} · {cost.calls} calls ({cost.cached_calls} cached) · ${cost.usd:.3f}{left}"
        )
        self.progress.update(self.task, description=desc, completed=s.generation,
                             total=s.total_generations)  # fmt: skip


def _run_with_progress(session):
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=False,
    ) as progress:
        unsubscribe = session.events.subscribe(_ProgressView(progress, session))
        try:
            return session.run()
        finally:
            unsubscribe()
            session.close()


def _print_summary(outcome, session, started: float) -> None:
    table = Table(title="Best transfer functions", show_lines=False)
    table.add_column("rank", justify="right")
    table.add_column("rating", justify="right")
    table.add_column("Gaussians (mean in data units, opacity)")
    lo, hi = session.volume.value_range
    for i, (tf, rating) in enumerate(outcome.best, start=1):
        desc = ", ".join(
            f"{lo + g.mean * (hi - lo):.4g}:{g.height:.2f}"
            for g in sorted(tf.gaussians, key=lambda g: g.mean)
        )
        table.add_row(str(i), f"{rating:.0f}", desc)
    console.print(table)
    c = outcome.cost
    # The run's cost counts requests of unknown fate (a killed process recorded them before
    # sending; some may never have left it), as its budget does; the summary names them apart
    # so that "paid" is only what was answered.
    lost_calls, lost_usd = _lost_requests(outcome)
    console.print(
        f"{outcome.generations_done} generation(s), {max(0, c.calls - lost_calls)} paid call(s), "
        f"{c.cached_calls} from cache, {c.input_tokens + c.output_tokens} tokens, "
        f"${max(0.0, c.usd - lost_usd):.4f}, {time.perf_counter() - started:.1f} s."
    )
    if lost_calls:
        console.print(
            f"…plus {lost_calls} request(s) a stopped process recorded without seeing the answer "
            f"(about ${lost_usd:.4f}): the server may have seen and billed them, so the budget "
            "counts them."
        )
    _print_match_stats(outcome)
    if outcome.run_dir is not None:
        color = "green" if outcome.completed else "yellow"
        console.print(f"[{color}]{escape(outcome.message)}[/]")
        report = outcome.run_dir / "report.html"
        # Paths and commands to copy: soft wrap (the terminal's), never a newline inside.
        console.print(
            f"Results: [bold]{outcome.run_dir}[/]"
            + (f"  (report: {report})" if report.exists() else ""),
            soft_wrap=True,
        )
        if not outcome.completed:
            console.print(
                f"Continue with: intuitf optimize --resume {outcome.run_dir}", soft_wrap=True
            )


def _print_lock_note(session) -> None:
    """Say so when this process took the run folder over from one that died holding it."""
    lock = getattr(session, "lock", None) or getattr(session, "_lock", None)
    note = getattr(lock, "takeover_message", None)
    if note:
        console.print(f"[yellow]note:[/] {escape(note)}")


def _print_match_stats(outcome) -> None:
    """Decided, undecided and re-asked matches of the whole run (from its journal)."""
    if outcome.run_dir is None:
        return
    from intuitf.evaluator.tournament import MatchStats
    from intuitf.session import RunDirectory
    from intuitf.session.outputs import indistinct_note

    generations = RunDirectory(outcome.run_dir).generations()
    stats = MatchStats.from_journal(generations)
    if stats.matches:
        console.print(escape(stats.summary()) + ".")
        if stats.warning:
            console.print(f"[yellow]warning:[/] {escape(stats.warning)}")
    note = indistinct_note(generations)
    if note:
        console.print(f"[yellow]note:[/] {escape(note)}")


def register(app: typer.Typer) -> None:
    @app.command()
    def optimize(
        volume: str = typer.Argument(
            None, help="Volume file or folder (or 'phantom'). Not needed with --resume."
        ),
        text: str = typer.Option(None, "--text", help="What you want, in words."),
        image: Path = typer.Option(
            None, "--image", help="A reference picture whose style to match."
        ),
        sketch: Path = typer.Option(
            None, "--sketch", help="Coloured strokes (PNG with transparency)."
        ),
        on: Path = typer.Option(None, "--on", help="The rendering the sketch was drawn on."),
        about: str = typer.Option(
            None, "--about", help="What the volume is, e.g. 'a CT of a human foot'."
        ),
        evaluator: str = typer.Option(
            None,
            "--evaluator",
            help="metric | openai:MODEL | gemini:MODEL | ollama:MODEL | vllm:MODEL | lmstudio:MODEL | openrouter:MODEL | URL",
        ),
        base_url: str = typer.Option(
            None, "--base-url", help="Server URL for an OpenAI-compatible model."
        ),
        population: int = typer.Option(32, "--population"),
        generations: int = typer.Option(12, "--generations"),
        gaussians: int = typer.Option(5, "--gaussians"),
        budget_usd: float = typer.Option(
            None, "--budget-usd", min=0.0, help="Stop cleanly before spending more."
        ),
        budget_calls: int = typer.Option(
            None, "--budget-calls", min=0, help="Stop cleanly before more model calls."
        ),
        request_timeout: float = typer.Option(
            None,
            "--request-timeout",
            min=0.001,
            help="Seconds to wait for one model request (default 30, or [judge] in the config).",
        ),
        answer_deadline: float = typer.Option(
            None,
            "--answer-deadline",
            min=0.001,
            help="Seconds to get one answer, retries included (default 60, or the config).",
        ),
        max_concurrency: jo.MaxConcurrencyOpt = None,
        max_output_tokens: jo.MaxOutputTokensOpt = None,
        reasoning_effort: jo.ReasoningEffortOpt = None,
        price: jo.PriceOpt = None,
        unpriced: jo.UnpricedOpt = False,
        seed: int = typer.Option(0, "--seed"),
        explorer: vo.ExplorerOpt = "ga",
        protocol: vo.ProtocolOpt = "efficient",
        size: int = typer.Option(
            None,
            "--size",
            help="Image size for judging (default 256, or the size of the --on picture).",
        ),
        output_size: int = typer.Option(
            512, "--output-size", help="Image size of the best renderings."
        ),
        top: int = typer.Option(4, "--top", help="How many best TFs to keep."),
        shading: bool = typer.Option(True, "--shading/--no-shading"),
        device: str = typer.Option(
            "auto",
            "--device",
            metavar="auto|cpu|cuda",
            help="Where to render: cuda (an NVIDIA GPU), cpu, or auto (the GPU when usable).",
        ),
        palette: bool = typer.Option(
            True,
            "--palette/--no-palette",
            help="Draw part of the new colours from those the intent asks for (the reference "
            "picture's, the sketch's, or the colours named in --text).",
        ),
        hints: bool = typer.Option(
            True,
            "--hints/--no-hints",
            help="Seed the first population, and steer colour and opacity mutations, from the "
            "materials --text names (e.g. 'opaque ivory bone': ivory, opaque, on the bone).",
        ),
        fit_sketch: bool = typer.Option(
            True,
            "--fit-sketch/--no-fit-sketch",
            help="With --sketch: fit a TF to the strokes first (a few seconds); it joins the "
            "first generation, and the run judges against the strokes from the start.",
        ),
        azimuth: float = typer.Option(
            None, "--azimuth", help="Judging view (default 30, or the --on picture's camera)."
        ),
        elevation: float = typer.Option(
            None, "--elevation", help="Judging view (default 20, or the --on picture's camera)."
        ),
        refine: Path = typer.Option(
            None,
            "--refine",
            help="Refine this TF JSON: only the --select'ed Gaussians change, as --text says.",
        ),
        select: str = typer.Option(
            None,
            "--select",
            help="With --refine: Gaussians to change, 1-based as listed in the TF JSON, e.g. 2,3.",
        ),
        start_from: list[Path] = typer.Option(
            None, "--start-from", help="TF JSON to include in the first population (repeatable)."
        ),
        output: Path = typer.Option(
            None, "-o", "--output", help="Run folder (default: runs/<volume>, -2, ... if taken)."
        ),
        resume: Path = typer.Option(None, "--resume", help="Continue the run in this folder."),
        overwrite: bool = typer.Option(
            False, "--overwrite", help="Replace a run already in the output folder."
        ),
        shape: vo.ShapeOpt = None,
        dtype: vo.DtypeOpt = None,
        byte_order: vo.ByteOrderOpt = None,
        spacing: vo.SpacingOpt = None,
        max_dim: vo.MaxDimOpt = None,
    ) -> None:
        """Find transfer functions that match what you want, unattended."""

        from intuitf.session import Session
        from intuitf.session.spec import parse_spec
        from intuitf.session.store import RunStore

        started = time.perf_counter()
        timeouts = dict(request_timeout=request_timeout, answer_deadline=answer_deadline)
        judged = jo.judge_options(
            max_concurrency, max_output_tokens, reasoning_effort, price, unpriced
        )
        if resume is not None:
            session = Session.resume(
                resume,
                evaluator=evaluator,
                base_url=base_url,
                budget_usd=budget_usd,
                budget_calls=budget_calls,
                judge_options={**_timeout_options(timeouts), **judged},
            )
            _print_lock_note(session)
            if session.judge_moved:
                console.print(
                    f"Moving this run to [bold]{escape(_where(session))}[/] from generation "
                    f"{session.generation + 1} on (recorded in run.json)."
                )
            if session.done:
                console.print("[green]This run is already complete.[/] Rewriting its outputs.")
        else:
            if volume is None:
                raise IntuitfError("Give a VOLUME to optimize (or 'phantom'), or --resume RUN_DIR.")
            if text is not None and not text.strip():
                raise IntuitfError(
                    "--text is empty.", "Say what you want in words, or leave --text out."
                )
            from intuitf.render.device import select_device

            select_device(device)  # a missing GPU is reported before any work
            volume_spec = {"source": volume, **vo.volume_kwargs(shape, dtype, byte_order,
                                                                spacing, max_dim)}  # fmt: skip
            view = judging_view(sketch, on, azimuth, elevation, size, _volume_name(volume))
            for note in view.notes:
                console.print(f"[yellow]note:[/] {escape(note)}")
            settings = dict(
                population=population, generations=generations, n_gaussians=gaussians, seed=seed,
                explorer=str(explorer), protocol=str(protocol), image_size=view.size,
                output_size=output_size, top_k=top, shading=shading,
                camera={} if view.default else view.camera,
                palette_hint=palette, material_hints=hints, device=device,
                fit_sketch=fit_sketch,
            )  # fmt: skip
            intent = _intent_spec(text, image, sketch, on, about)
            initial = [load_tf(p).to_dict() for p in start_from or []]
            if refine is not None:
                tf_dict, picked = _refinement(refine, select, text)
                intent = {"kind": "edit", "text": text, "about": about, "selected": picked}
                initial = [tf_dict]
            spec = {
                "volume": volume_spec,
                "intent": intent,
                "judge": _judge_spec(
                    evaluator, base_url, budget_usd, budget_calls, timeouts, judged
                ),
                "settings": settings,
                "initial": initial,
            }
            # Named by the session's one rule (runs/foot, runs/foot-2, ...), as the web names.
            run_dir = output or RunStore(Path("runs")).new_run_dir(_volume_name(volume))
            with flag_errors():
                parse_spec(spec)  # every bad option named before anything is written
            _check_can_create(run_dir)
            with flag_errors():
                try:
                    session = Session.open(spec, run_dir, overwrite=overwrite)
                except OSError as exc:  # a folder that cannot be made, a disk that is full
                    raise IntuitfError(
                        f"Cannot write the run folder {run_dir}: {exc.strerror or exc}.",
                        "Choose a folder you can write to with -o.",
                    ) from None
            for note in session.volume.notes:
                console.print(f"[yellow]note:[/] {escape(note)}")
            _print_lock_note(session)
        console.print(
            f"Optimizing [bold]{session.volume.name}[/] with {getattr(session.judge, 'name', 'judge')}: "
            f"population {session.settings.population}, {session.total_generations} generations "
            f"({', '.join(f'{s} {n}' for s, n in session.plan)}); run folder {session.run_dir.root}"
        )
        _print_understood(session)
        outcome = _run_with_progress(session)
        _print_summary(outcome, session, started)
        if not outcome.completed:
            raise typer.Exit(3 if outcome.reason != "interrupted" else 130)

    @app.command()
    def demo(
        output: Path = typer.Option(
            Path("intuitf-output/demo"), "-o", "--output", help="Run folder."
        ),
        generations: int = typer.Option(8, "--generations"),
        population: int = typer.Option(24, "--population"),
    ) -> None:
        """Run the main job end to end on built-in inputs: phantom volume, offline judge, a text intent."""
        from intuitf.session import Session
        from intuitf.volume import phantom

        started = time.perf_counter()
        vol = phantom()
        console.print(
            f"Demo: optimizing the built-in phantom for “{DEMO_TEXT}” with the offline metric judge."
        )
        spec = {
            "volume": "phantom",
            "intent": {"kind": "text", "text": DEMO_TEXT, "about": DEMO_ABOUT},
            "judge": "metric",
            "settings": dict(population=population, generations=generations, seed=0,
                             image_size=160, output_size=384, top_k=4, camera=default_camera()),
        }  # fmt: skip
        session = Session.open(spec, output, overwrite=True, volume=vol)
        outcome = _run_with_progress(session)
        _print_summary(outcome, session, started)
        if outcome.run_dir is not None and (outcome.run_dir / "report.html").exists():
            console.print(
                f"Open {outcome.run_dir / 'report.html'} in a browser to see the results.",
                soft_wrap=True,
            )


def _print_understood(session) -> None:
    """How the intent was read on the volume (words to structures, strokes to values), so a
    colour on the wrong part is explained before the first generation ends."""
    lines = getattr(session, "understood", None) or []
    if lines:
        console.print("Understood:")
        for line in lines:
            console.print(f"  {escape(line)}", soft_wrap=True)


def _check_can_create(folder: Path) -> None:
    """Say so before any work when ``folder`` cannot be made: its nearest existing parent is
    a file, or a folder this user cannot write to."""
    import os

    p = Path(folder).expanduser().absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    if not p.is_dir():
        raise IntuitfError(
            f"Cannot make the run folder {folder}: {p} is a file.",
            "Choose another folder with -o.",
        )
    if not os.access(p, os.W_OK | os.X_OK):
        raise IntuitfError(
            f"Cannot make the run folder {folder}: {p} is not writable.",
            "Choose a folder you can write to with -o.",
        )


def _volume_name(source: str) -> str:
    name = Path(source).name
    for suffix in (".gz", ".raw", ".nrrd", ".nhdr", ".nii", ".mha", ".mhd", ".vti", ".npy",
                   ".npz", ".tif", ".tiff", ".cvol"):  # fmt: skip
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
    return name or "volume"


def _refinement(tf_path: Path, select: str | None, text: str | None) -> tuple[dict, list[int]]:
    """The TF to refine and the 0-based indices of the Gaussians --select names (1-based)."""
    if not select or not text:
        raise IntuitfError(
            "--refine needs --select (which Gaussians to change) and --text (what to change).",
            'For example: --refine best.tf.json --select 2 --text "make the bone gold"',
        )
    tf = load_tf(tf_path)
    try:
        picked = [int(x) - 1 for x in select.split(",") if x.strip()]
    except ValueError as exc:
        raise IntuitfError(f"--select takes numbers like 1,3; got {select!r}.") from exc
    if not picked or min(picked) < 0 or max(picked) >= len(tf):
        raise IntuitfError(
            f"--select must name Gaussians 1..{len(tf)} of {tf_path}; got {select!r}."
        )
    return tf.to_dict(), picked


def _where(session) -> str:
    """The run's judge and server, credentials redacted."""
    from intuitf.evaluator.providers import redact_url

    j = session.spec.judge
    return redact_url(j.spec) + (f" at {redact_url(j.base_url)}" if j.base_url else "")


def _lost_requests(outcome) -> tuple[int, float]:
    """Requests a killed process recorded but never saw answered, and their estimated price."""
    from intuitf.session.rundir import RunDirectory

    store = RunDirectory(outcome.run_dir).verdicts if outcome.run_dir is not None else None
    if store is None or not store.exists():
        return 0, 0.0
    from intuitf.evaluator.cache import VerdictCache

    with VerdictCache(store) as cache:
        calls, usd = cache.unsettled()
    return int(calls), float(usd)
