"""``intuitf export`` and ``intuitf report``: hand results to other tools and to people."""

from __future__ import annotations

import math
from pathlib import Path

import typer
from rich.console import Console

from intuitf.cli.options import choices
from intuitf.errors import IntuitfError, TransferFunctionError
from intuitf.tf.export import EXPORT_FORMATS

console = Console()

#: The formats ``export --to`` takes (checked by the command line, listed when wrong).
ExportFormat = choices("ExportFormat", EXPORT_FORMATS)


def parse_value_range(text: str | None) -> tuple[float, float] | None:
    """``"LO,HI"`` -> ``(lo, hi)``; ``None`` stays ``None``."""
    if text is None:
        return None
    parts = [p.strip() for p in text.split(",")]
    try:
        lo, hi = (float(p) for p in parts)
    except ValueError:
        raise TransferFunctionError(
            f"--value-range must be two numbers LO,HI, got {text!r}.",
            "Write it like --value-range -1024,3071 (no spaces needed).",
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise TransferFunctionError(
            f"--value-range needs LO < HI, both finite, got {text!r}.",
            "Give the lowest and highest value of the data, e.g. --value-range 0,255.",
        )
    return lo, hi


def register(app: typer.Typer) -> None:
    """Add ``export`` and ``report`` to ``app``."""

    @app.command("export")
    def export(
        tf_file: Path = typer.Argument(..., help="Transfer function JSON written by intuitf."),
        to: ExportFormat = typer.Option(
            ...,
            "--to",
            help="Target format.",
            case_sensitive=False,
            show_default=False,
        ),
        output: Path | None = typer.Option(
            None,
            "-o",
            "--output",
            help="File to write (default: next to the TF, with the format's suffix).",
        ),
        value_range: str | None = typer.Option(
            None,
            "--value-range",
            help="LO,HI of the data in its own units (needed when the TF does not record it).",
        ),
        voxel_size: float = typer.Option(
            1.0,
            "--voxel-size",
            help="World length of one voxel (the unit of the TF's opacities).",
        ),
    ) -> None:
        """Write a transfer function for ParaView, 3D Slicer, VTK (Python) or ImageVis3D."""
        from intuitf.tf import load_tf
        from intuitf.tf.export_io import export_path, write_export

        fmt = ExportFormat(to).value
        vr = parse_value_range(value_range)
        tf = load_tf(tf_file)
        if output is None:
            stem = tf_file.name.removesuffix(".json").removesuffix(".tf")
            output = export_path(tf_file.with_name(stem), fmt)
        path = write_export(tf, fmt, output, vr, unit_distance=voxel_size)
        console.print(f"Wrote {path}", soft_wrap=True)

    @app.command("report")
    def report(
        run_dir: Path = typer.Argument(..., help="Run folder written by `intuitf optimize`."),
    ) -> None:
        """Build RUN_DIR/report.html, a self-contained page with the run's results."""
        from intuitf.report import build_report
        from intuitf.session.rundir import RunDirectory

        if not RunDirectory(run_dir).exists():
            why = "it does not exist" if not run_dir.exists() else "it holds no run.json"
            raise IntuitfError(
                f"{run_dir} is not a run folder ({why}).",
                "Give a run folder written by `intuitf optimize` (or a batch's runs/KEY).",
            )
        path = build_report(run_dir)
        console.print(f"Report: {path}", soft_wrap=True)
