"""``intuitf optimize`` (the main job) and ``intuitf demo`` (the main job on built-in inputs)."""

from __future__ import annotations

import shutil
import time
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

from intuitf.cli import options as vo
from intuitf.errors import IntuitfError, SessionError
from intuitf.evaluator.factory import judge_record

console = Console()

DEMO_TEXT = "opaque ivory bone, faint red skin"
DEMO_ABOUT = "a CT-like phantom of a human head"


def _build_intent(text, image, sketch, on, about):
    from intuitf.evaluator.types import Intent
    from intuitf.imageio import load_image, load_image_rgba

    if sketch is not None:
        if on is None:
            raise IntuitfError(
                "--sketch needs --on BASE.png: the rendering the strokes were drawn on."
            )
        return Intent(
            kind="sketch",
            text=text,
            sketch=load_image_rgba(sketch),
            base=load_image(on),
            about=about,
        )
    if image is not None:
        return Intent(kind="image", text=text, reference=load_image(image), about=about)
    if text:
        return Intent(kind="text", text=text, about=about)
    return Intent(kind="none", about=about)


def _make_judge(
    spec: str,
    run_dir: Path,
    base_url,
    budget_usd,
    budget_calls,
    resumed=False,
    protocol="efficient",
    request_timeout=None,
    answer_deadline=None,
):
    from intuitf.evaluator.budget import Budget
    from intuitf.evaluator.cache import VerdictCache
    from intuitf.evaluator.factory import make_judge

    # The efficient tournament shows each pair in a seeded random order and re-asks only
    # surprising verdicts in the other order, so the judge asks once per match; the paper's
    # protocol asks every pair in both orders.
    options = {"swap": "never" if protocol == "efficient" else "always"}
    if base_url:
        options["base_url"] = base_url
    if request_timeout is not None:
        options["timeout"] = request_timeout
    if answer_deadline is not None:
        options["deadline"] = answer_deadline
    budget = None
    if budget_usd is not None or budget_calls is not None:
        budget = Budget(max_usd=budget_usd, max_calls=budget_calls)
    if spec == "metric":
        return make_judge(spec)
    created = not run_dir.exists()
    run_dir.mkdir(parents=True, exist_ok=True)
    try:
        cache = VerdictCache(run_dir / "verdicts.sqlite")
        if resumed and budget is not None:
            # A resumed run's budget covers the whole run: what the store says was paid
            # (exact, also for an interrupted generation and calls a killed process had out).
            budget.restore(cache.spent(), *cache.unsettled())
        return make_judge(spec, cache=cache, budget=budget, **options)
    except IntuitfError:
        # A bad spec or a missing API key must not leave an empty run folder behind.
        if created:
            shutil.rmtree(run_dir, ignore_errors=True)
        raise


class _ProgressView:
    """Rich progress: generation, tournament round, calls, cost so far, time left."""

    def __init__(self, progress: Progress) -> None:
        self.progress = progress
        self.task = None

    def __call__(self, e) -> None:
        if self.task is None:
            self.task = self.progress.add_task(
                "starting", total=e.generations, completed=e.generation
            )
        left = ""
        if e.seconds_per_generation:
            remaining = (e.generations - e.generation) * e.seconds_per_generation
            left = f" · ~{remaining:.0f}s left"
        what = {
            "generation_start": "rendering",
            "rendered": "judging",
            "round": f"round {e.round}/{e.rounds}",
            "generation_end": "done",
            "end": "finished",
        }.get(e.kind, e.kind)
        desc = (
            f"gen {min(e.generation + 1, e.generations)}/{e.generations} [{e.stage}] {what} · "
            f"{e.cost.calls} calls ({e.cost.cached_calls} cached) · ${e.cost.usd:.3f}{left}"
        )
        self.progress.update(self.task, description=desc, completed=e.generation)


def _run_with_progress(session):
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=False,
    ) as progress:
        try:
            return session.run(_ProgressView(progress))
        finally:
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
    console.print(
        f"{outcome.generations_done} generation(s), {c.calls} paid call(s), {c.cached_calls} from cache, "
        f"{c.input_tokens + c.output_tokens} tokens, ${c.usd:.4f}, {time.perf_counter() - started:.1f} s."
    )
    _print_match_stats(outcome)
    if outcome.run_dir is not None:
        color = "green" if outcome.completed else "yellow"
        console.print(f"[{color}]{escape(outcome.message)}[/]")
        console.print(
            f"Results: [bold]{outcome.run_dir}[/]  (report: {outcome.run_dir / 'report.html'})"
        )
        if not outcome.completed:
            console.print(f"Continue with: intuitf optimize --resume {outcome.run_dir}")


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

    stats = MatchStats.from_journal(RunDirectory(outcome.run_dir).generations())
    if stats.matches:
        console.print(escape(stats.summary()) + ".")
        if stats.warning:
            console.print(f"[yellow]warning:[/] {escape(stats.warning)}")


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
        seed: int = typer.Option(0, "--seed"),
        explorer: str = typer.Option("ga", "--explorer", help="ga | cmaes | random | paper-ga"),
        protocol: str = typer.Option(
            "efficient", "--protocol", help="efficient | paper (tournament)"
        ),
        size: int = typer.Option(256, "--size", help="Image size for judging."),
        output_size: int = typer.Option(
            512, "--output-size", help="Image size of the best renderings."
        ),
        top: int = typer.Option(4, "--top", help="How many best TFs to keep."),
        shading: bool = typer.Option(True, "--shading/--no-shading"),
        palette: bool = typer.Option(
            True,
            "--palette/--no-palette",
            help="Draw part of the new colours from those the intent asks for (the reference "
            "picture's, the sketch's, or the colours named in --text).",
        ),
        azimuth: float = typer.Option(None, "--azimuth"),
        elevation: float = typer.Option(None, "--elevation"),
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
            None, "-o", "--output", help="Run folder (default: runs/<volume>-<time>)."
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

        started = time.perf_counter()
        timeouts = dict(request_timeout=request_timeout, answer_deadline=answer_deadline)
        if resume is not None:
            session = _resume_session(
                resume, budget_usd, budget_calls, base_url, evaluator, **timeouts
            )
        else:
            evaluator = evaluator or "metric"
            if volume is None:
                raise IntuitfError("Give a VOLUME to optimize (or 'phantom'), or --resume RUN_DIR.")
            vol_args = dict(
                shape=shape, dtype=dtype, byte_order=byte_order, spacing=spacing, max_dim=max_dim
            )
            vol = vo.open_volume(volume, **vol_args)
            for note in vol.notes:
                console.print(f"[yellow]note:[/] {escape(note)}")
            intent = _build_intent(text, image, sketch, on, about)
            run_dir = output or Path("runs") / f"{vol.name}-{time.strftime('%Y%m%d-%H%M%S')}"
            settings_kw = dict(
                population=population, generations=generations, n_gaussians=gaussians, seed=seed,
                explorer=explorer, protocol=protocol, image_size=size, output_size=output_size,
                top_k=top, shading=shading, camera=_camera_dict(azimuth, elevation),
                palette_hint=palette,
            )  # fmt: skip
            record = {
                "volume_source": volume,
                "volume_args": vol_args,
                **judge_record(evaluator, base_url),
            }
            if refine is not None:
                session = _refine_session(
                    vol, refine, select, text, about, evaluator, base_url, run_dir, settings_kw,
                    budget_usd, budget_calls, overwrite, record, timeouts,
                )  # fmt: skip
            else:
                session = _new_session(
                    vol, intent, evaluator, base_url, run_dir, settings_kw, budget_usd,
                    budget_calls, start_from or [], overwrite, record, timeouts,
                )  # fmt: skip
        _print_lock_note(session)
        console.print(
            f"Optimizing [bold]{session.volume.name}[/] with {getattr(session.judge, 'name', 'judge')}: "
            f"population {session.settings.population}, {session.total_generations} generations "
            f"({', '.join(f'{s} {n}' for s, n in session.plan)}); run folder {session.run_dir.root}"
        )
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
        from intuitf.evaluator.types import Intent
        from intuitf.volume import phantom

        started = time.perf_counter()
        vol = phantom()
        intent = Intent(kind="text", text=DEMO_TEXT, about=DEMO_ABOUT)
        console.print(
            f"Demo: optimizing the built-in phantom for “{DEMO_TEXT}” with the offline metric judge."
        )
        session = _new_session(
            vol,
            intent,
            "metric",
            None,
            output,
            dict(
                population=population,
                generations=generations,
                seed=0,
                image_size=160,
                output_size=384,
                top_k=4,
            ),
            None,
            None,
            [],
            True,
            {
                "volume_source": "phantom",
                "volume_args": {},
                "evaluator": "metric",
                "base_url": None,
            },
        )
        outcome = _run_with_progress(session)
        _print_summary(outcome, session, started)
        if outcome.run_dir is not None:
            console.print(
                f"Open {outcome.run_dir / 'report.html'} in a browser to see the results."
            )


def _camera_dict(azimuth, elevation) -> dict:
    d = {}
    if azimuth is not None:
        d["azimuth"] = azimuth
    if elevation is not None:
        d["elevation"] = elevation
    if not d:
        return {}
    from intuitf.render import Camera

    return Camera(**d).to_dict()


def _new_session(
    vol,
    intent,
    evaluator,
    base_url,
    run_dir,
    settings_kw,
    budget_usd,
    budget_calls,
    start_from,
    overwrite,
    record,
    timeouts=None,
):
    from intuitf.session import Session
    from intuitf.tf import load_tf

    settings, run_dir, judge = _prepare_run(
        settings_kw, run_dir, overwrite, evaluator, base_url, budget_usd, budget_calls,
        **(timeouts or {}),
    )  # fmt: skip
    initial = [load_tf(p) for p in start_from]
    return Session.create(
        vol,
        intent=intent,
        judge=judge,
        settings=settings,
        run_dir=run_dir,
        initial=initial,
        overwrite=overwrite,
        extra_record=record,
    )


def _prepare_run(
    settings_kw, run_dir, overwrite, evaluator, base_url, budget_usd, budget_calls, **timeouts
):
    """Validated settings, a run folder that holds no other run, and the judge for it."""
    from intuitf.session import RunSettings

    settings = RunSettings(**settings_kw)
    settings.validate()
    run_dir = Path(run_dir)
    if (run_dir / "run.json").exists() and not overwrite:
        raise SessionError(
            f"{run_dir} already holds a run.",
            f"Continue it with --resume {run_dir}, or pick another folder with -o (or --overwrite).",
        )
    judge = _make_judge(
        evaluator, run_dir, base_url, budget_usd, budget_calls, protocol=settings.protocol,
        **timeouts,
    )  # fmt: skip
    return settings, run_dir, judge


def _refine_session(
    vol, tf_path, select, text, about, evaluator, base_url, run_dir, settings_kw,
    budget_usd, budget_calls, overwrite, record, timeouts=None,
):  # fmt: skip
    from intuitf.session import Session
    from intuitf.tf import load_tf

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
    settings, run_dir, judge = _prepare_run(
        settings_kw, run_dir, overwrite, evaluator, base_url, budget_usd, budget_calls,
        **(timeouts or {}),
    )  # fmt: skip
    return Session.refine(
        vol, tf, picked, text, judge=judge, settings=settings, run_dir=run_dir, about=about,
        overwrite=overwrite, extra_record=record,
    )  # fmt: skip


def _resume_session(run_dir: Path, budget_usd, budget_calls, base_url, evaluator=None, **timeouts):
    from intuitf.evaluator.factory import record_judge_move, resume_judge_spec
    from intuitf.session import RunDirectory, Session

    rd = RunDirectory(run_dir)
    record = rd.read_run()
    vol = vo.open_volume(record.get("volume_source", "phantom"), **record.get("volume_args", {}))
    # --evaluator / --base-url on a resume move the run to another model or server.
    spec, url, moved = resume_judge_spec(record, evaluator, base_url)
    judge = _make_judge(
        spec,
        rd.root,
        url,
        budget_usd,
        budget_calls,
        resumed=True,
        protocol=record.get("settings", {}).get("protocol", "efficient"),
        **timeouts,
    )
    session = Session.resume(rd.root, vol, judge)
    _print_lock_note(session)
    if moved:
        record = rd.read_run()  # as the resume left it
        entry = record_judge_move(record, spec, url, session.generation)
        rd.write_run(record)
        rd.append_journal({"type": "judge", **entry})
        console.print(
            f"Moving this run to [bold]{escape(entry['evaluator'])}[/]"
            + (f" at {escape(entry['base_url'])}" if entry.get("base_url") else "")
            + f" from generation {entry['from_generation'] + 1} on (recorded in run.json)."
        )
    if session.done:
        console.print("[green]This run is already complete.[/] Rewriting its outputs.")
    return session
