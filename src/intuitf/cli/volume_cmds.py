"""``intuitf info``: what a volume holds (size, type, range, spacing, histogram, materials)."""

from __future__ import annotations

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from intuitf.cli import options as vo
from intuitf.tf import find_materials
from intuitf.volume import Volume

_BARS = " ▁▂▃▄▅▆▇█"


def sparkline(counts: np.ndarray, width: int = 64) -> str:
    """A one-line text picture of a histogram's log counts, ``width`` characters wide."""
    c = np.asarray(counts, dtype=np.float64)
    groups = np.array_split(c, min(width, c.size))
    logc = np.log1p([g.sum() for g in groups])
    top = logc.max()
    if top <= 0:
        return _BARS[0] * len(groups)
    idx = np.rint(logc / top * (len(_BARS) - 1)).astype(int)
    return "".join(_BARS[i] for i in idx)


def _num(v: float) -> str:
    return f"{v:.6g}"


def info_table(vol: Volume) -> Table:
    """A Rich table of the facts ``intuitf info`` prints about ``vol``."""
    s = vol.summary()
    lo, hi = vol.value_range
    counts, _ = vol.histogram(256)
    t = Table(title=f"Volume: {vol.name}", show_header=False, title_justify="left")
    t.add_column("field", style="bold cyan", no_wrap=True)
    t.add_column("value")
    t.add_row("source", str(vol.source))
    t.add_row("shape (x, y, z)", " x ".join(str(d) for d in vol.dims))
    t.add_row("voxels", f"{int(np.prod(vol.dims)):,}")
    t.add_row("dtype", vol.original_dtype)
    t.add_row("value range", f"{_num(lo)} .. {_num(hi)}")
    t.add_row("mean", _num(s["mean"]))
    t.add_row("spacing (x, y, z)", ", ".join(_num(v) for v in vol.spacing))
    t.add_row("physical size", " x ".join(_num(v) for v in vol.extent))
    t.add_row("LUT size", str(vol.lut_size))
    spark = sparkline(counts, width=48)
    half = len(spark) // 2
    t.add_row(
        "histogram (log)",
        f"[green]{spark}[/]\n{_num(lo):<{half}}{_num(hi):>{len(spark) - half}}",
    )
    mats = find_materials(counts)
    if mats:
        lines = [
            f"{_num(vol.to_original(m.center))}  (± {_num(m.spread * (hi - lo))}, "
            + (f"{100 * m.fraction:.1f}% of foreground)" if m.fraction > 0 else "upper tail)")
            for m in mats
        ]
        t.add_row("materials", "\n".join(lines))
    t.add_row("notes", "\n".join(vol.notes) if vol.notes else "-")
    return t


def info(
    volume: vo.VolumeArg,
    shape: vo.ShapeOpt = None,
    dtype: vo.DtypeOpt = None,
    byte_order: vo.ByteOrderOpt = None,
    spacing: vo.SpacingOpt = None,
    max_dim: vo.MaxDimOpt = None,
) -> None:
    """Show a volume's size, type, value range, spacing, histogram and materials."""
    vol = vo.open_volume(volume, shape, dtype, byte_order, spacing, max_dim)
    Console().print(info_table(vol))


def register(app: typer.Typer) -> None:
    """Add this module's commands to ``app``."""
    app.command("info")(info)
