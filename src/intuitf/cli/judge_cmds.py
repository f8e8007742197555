"""``intuitf judge-agreement``: how often a judge agrees with people's labels on image pairs."""

from __future__ import annotations

import asyncio
from pathlib import Path

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from intuitf.errors import IntuitfError
from intuitf.evaluator.agreement import evaluate_agreement, parse_pairs
from intuitf.evaluator.types import Intent
from intuitf.intent.aspects import aspects_for, builtin_catalogue


def _image_loader(folder: Path):
    """Load and memoise images by the path written in the labels (relative to ``folder``)."""
    from PIL import Image

    cache: dict[str, np.ndarray] = {}

    def load(path: str) -> np.ndarray:
        if path not in cache:
            p = Path(path).expanduser()
            p = p if p.is_absolute() else folder / p
            try:
                with Image.open(p) as im:
                    cache[path] = np.asarray(im.convert("RGB"), dtype=np.uint8)
            except (OSError, ValueError) as exc:
                raise IntuitfError(
                    f"Image {p} could not be read ({exc}).",
                    "Check the path in the labels file (relative paths start at its folder).",
                ) from None
        return cache[path]

    return load


def judge_agreement(
    pairs_file: Path = typer.Argument(..., help="JSONL labels (see intuitf.evaluator.agreement)."),
    evaluator: str = typer.Option("metric", "--evaluator", "-e", help="Judge spec, e.g. metric."),
    aspects: str = typer.Option(
        None,
        "--aspects",
        help="Aspect set: quality, text, image, sketch, edit (default: by intent).",
    ),
    text: str = typer.Option(None, "--text", help="Text intent for pairs that carry none."),
    base_url: str = typer.Option(None, "--base-url", help="OpenAI-compatible server URL."),
) -> None:
    """Score a judge's agreement with human labels: 1/N Σ p·q + (1-p)(1-q), overall and per aspect."""
    from intuitf.evaluator.factory import make_judge

    if not pairs_file.is_file():
        raise IntuitfError(
            f"Labels file {pairs_file} does not exist.", "Give the path of a .jsonl labels file."
        )
    try:
        lines = pairs_file.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise IntuitfError(
            f"Labels file {pairs_file} could not be read ({exc}).", "Give a UTF-8 JSONL file."
        ) from None
    pairs = parse_pairs(lines, source=str(pairs_file))
    options = {"base_url": base_url} if base_url and evaluator != "metric" else {}
    judge = make_judge(evaluator, **options)
    set_key = aspects or ("text" if text else "quality")
    chosen = aspects_for(set_key)
    intent = Intent(kind="text", text=text) if text else Intent()
    loader = _image_loader(pairs_file.resolve().parent)

    async def evaluate():
        try:
            return await evaluate_agreement(
                judge, pairs, loader, chosen, aspect_lookup=builtin_catalogue().get, intent=intent
            )
        finally:
            close = getattr(judge, "aclose", None)  # close the HTTP client in its own loop
            if close is not None:
                await close()

    report = asyncio.run(evaluate())
    table = Table(title=f"Agreement of {judge.name} with {pairs_file.name}", title_justify="left")
    table.add_column("aspect", style="cyan")
    table.add_column("pairs", justify="right")
    table.add_column("agreement", justify="right")
    for key, (score, n) in report.per_aspect.items():
        table.add_row(key, str(n), f"{score:.3f}")
    table.add_row("[bold]all[/]", f"[bold]{report.n}[/]", f"[bold]{report.score:.3f}[/]")
    console = Console()
    console.print(table)
    c = report.cost
    console.print(
        f"model calls {c.calls} (cached {c.cached_calls}), unusable answers {report.errors}, "
        f"${c.usd:.4f}"
    )


def register(app: typer.Typer) -> None:
    """Add ``judge-agreement`` to the ``intuitf`` command."""
    app.command("judge-agreement")(judge_agreement)
