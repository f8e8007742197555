"""Pictures for people: a TF over the histogram, contact sheets of renderings, run evolution.

Functions return PNG bytes or a uint8 RGB array; callers write files. Figures are built with
:class:`matplotlib.figure.Figure` and the Agg canvas, never pyplot, so they are safe to make
from worker threads (the web app) and need no display.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from PIL import Image, ImageDraw, ImageFont

from intuitf.tf.gaussian import GaussianTF

_DPI = 100
_INK = "#222222"
_MUTED = "#8a8a8a"
_GRID = "#e6e6e6"


def _png(fig: Figure) -> bytes:
    buf = io.BytesIO()
    FigureCanvasAgg(fig)
    fig.savefig(buf, format="png", dpi=_DPI, facecolor=fig.get_facecolor())
    return buf.getvalue()


def _style(ax) -> None:
    ax.tick_params(labelsize=8, colors=_INK, length=3)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)
    for side in ("left", "bottom"):
        ax.spines[side].set_color(_MUTED)
    ax.grid(True, color=_GRID, linewidth=0.6)
    ax.set_axisbelow(True)


# -- transfer function ----------------------------------------------------------------------
def tf_plot(
    tf: GaussianTF,
    histogram_counts: np.ndarray | None = None,
    size: tuple[int, int] = (640, 240),
) -> bytes:
    """PNG of ``tf``: its opacity curve filled with its colours, over the log histogram.

    Below the curve a band shows what is seen at each value: the colour, faded to a dark
    backdrop where the TF is transparent. Triangles mark each Gaussian's mean (hollow when frozen). The x axis
    is in the data's own units when ``tf.value_range`` is known. The opacity axis uses a square
    root scale so faint materials (skin at 0.02) stay visible beside opaque ones.
    """
    w, h = size
    s = np.linspace(0.0, 1.0, 1024)
    lo, hi = tf.value_range if tf.value_range is not None else (0.0, 1.0)
    x = lo + s * (hi - lo)
    a = tf.opacity(s)
    rgb = tf.color(s)
    top = max(0.05, float(a.max()) * 1.08)

    fig = Figure(figsize=(w / _DPI, h / _DPI), dpi=_DPI, facecolor="white")
    gs = fig.add_gridspec(
        2, 1, height_ratios=[6, 1], hspace=0.08, left=0.09, right=0.985, top=0.95, bottom=0.2
    )
    ax = fig.add_subplot(gs[0])
    band = fig.add_subplot(gs[1], sharex=ax)
    _style(ax)

    if histogram_counts is not None and len(histogram_counts) > 1:
        counts = np.asarray(histogram_counts, dtype=np.float64)
        logc = np.log1p(np.clip(counts, 0, None))
        logc = logc / logc.max() if logc.max() > 0 else logc
        edges = lo + np.linspace(0.0, 1.0, len(counts) + 1) * (hi - lo)
        hx = ax.twinx()
        hx.stairs(logc, edges, fill=True, color="#d9dde3", linewidth=0)
        hx.set_ylim(0, 1.05)
        hx.set_yticks([])
        for side in hx.spines.values():
            side.set_visible(False)
        hx.set_zorder(0)
        ax.set_zorder(1)
        ax.patch.set_visible(False)

    ax.set_yscale("function", functions=(np.sqrt, np.square))
    ax.set_ylim(0, top)
    ax.set_xlim(lo, hi)
    # The area under the curve painted with the TF's colour at each value.
    fill = ax.fill_between(x, 0, a, color="none", linewidth=0)
    img = ax.imshow(
        rgb[None, :, :],
        extent=(lo, hi, 0, top),
        aspect="auto",
        origin="lower",
        interpolation="bilinear",
        zorder=1,
    )
    img.set_clip_path(fill.get_paths()[0], transform=ax.transData)
    ax.plot(x, a, color=_INK, linewidth=1.2, zorder=3)
    for g in tf.gaussians:
        gx = lo + g.mean * (hi - lo)
        ga = float(tf.opacity(np.array([g.mean]))[0])
        ax.plot(
            [gx],
            [max(ga, top * 1e-4)],
            marker="v",
            markersize=7,
            markeredgecolor=_INK,
            markeredgewidth=0.8,
            markerfacecolor="white" if g.frozen else g.color,
            linestyle="none",
            zorder=4,
            clip_on=False,
        )
    ax.set_ylabel("opacity / voxel", fontsize=8, color=_INK)
    ax.tick_params(labelbottom=False)

    # What is seen: colour over a dark backdrop (like a rendering's), by opacity (square root,
    # as on the axis above), so white and pale materials show as well as saturated ones.
    seen = np.sqrt(np.clip(a / top, 0, 1))[:, None]
    strip = rgb * seen + np.array([0.106, 0.106, 0.122]) * (1.0 - seen)
    band.imshow(strip[None, :, :], extent=(lo, hi, 0, 1), aspect="auto", interpolation="bilinear")
    band.set_yticks([])
    band.tick_params(labelsize=8, colors=_INK, length=3)
    for side in band.spines.values():
        side.set_color(_MUTED)
    band.xaxis.set_major_locator(MaxNLocator(nbins=8))
    band.set_xlabel(
        "value" if tf.value_range is not None else "normalised value", fontsize=8, color=_INK
    )
    return _png(fig)


# -- contact sheet --------------------------------------------------------------------------
@lru_cache(maxsize=8)
def _font(px: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    try:
        return ImageFont.truetype("DejaVuSans.ttf", px)
    except OSError:
        return ImageFont.load_default(size=px)


def _as_rgb8(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] not in (3, 4):
        raise ValueError(f"contact_sheet: expected (H, W, 3|4) images, got shape {a.shape}.")
    if a.dtype != np.uint8:
        a = (np.clip(a.astype(np.float64), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    return np.ascontiguousarray(a[:, :, :3])


def _fit_caption(draw: ImageDraw.ImageDraw, text: str, font, width: int) -> str:
    if draw.textlength(text, font=font) <= width:
        return text
    while text and draw.textlength(text + "…", font=font) > width:
        text = text[:-1]
    return text + "…"


def contact_sheet(
    images: Sequence[np.ndarray],
    captions: Sequence[str],
    columns: int = 8,
    thumb: int = 160,
) -> np.ndarray:
    """A grid of renderings with a caption under each, as a uint8 RGB array.

    Images (uint8, or float in [0, 1]; RGB, RGBA or grey) are scaled to fit ``thumb`` pixels
    and centred in their cell; captions that do not fit are shortened with an ellipsis.
    """
    if len(images) != len(captions):
        raise ValueError(f"contact_sheet: {len(images)} images but {len(captions)} captions.")
    if not images:
        raise ValueError("contact_sheet: no images.")
    columns = max(1, min(int(columns), len(images)))
    rows = -(-len(images) // columns)
    pad, cap_h = 6, max(14, thumb // 9)
    font = _font(max(9, cap_h - 5))
    cell_w, cell_h = thumb + pad, thumb + cap_h + pad
    sheet = Image.new("RGB", (columns * cell_w + pad, rows * cell_h + pad), (24, 24, 27))
    draw = ImageDraw.Draw(sheet)
    for i, (image, caption) in enumerate(zip(images, captions, strict=True)):
        r, c = divmod(i, columns)
        x0, y0 = pad + c * cell_w, pad + r * cell_h
        tile = Image.fromarray(_as_rgb8(image))
        tile.thumbnail((thumb, thumb), Image.Resampling.LANCZOS)
        if max(tile.size) < thumb:  # small images grow to the cell too
            k = thumb / max(tile.size)
            tile = tile.resize(
                (max(1, round(tile.width * k)), max(1, round(tile.height * k))),
                Image.Resampling.LANCZOS,
            )
        draw.rectangle((x0, y0, x0 + thumb - 1, y0 + thumb - 1), fill=(0, 0, 0))
        sheet.paste(tile, (x0 + (thumb - tile.width) // 2, y0 + (thumb - tile.height) // 2))
        text = _fit_caption(draw, str(caption), font, thumb - 4)
        draw.text((x0 + 2, y0 + thumb + 2), text, fill=(228, 228, 231), font=font)
    return np.asarray(sheet, dtype=np.uint8)


# -- evolution ------------------------------------------------------------------------------
def evolution_plot(records: Sequence[dict], size: tuple[int, int] = (960, 300)) -> bytes:
    """PNG of a run's progress per generation: ratings (best, mean, worst), cumulative calls
    and cost, and cumulative time.

    ``records`` are dicts with keys generation, best_rating, mean_rating, min_rating, calls,
    cost_usd, seconds (per generation, not cumulative).
    """
    w, h = size
    fig = Figure(figsize=(w / _DPI, h / _DPI), dpi=_DPI, facecolor="white")
    axes = fig.subplots(
        1, 3, gridspec_kw={"wspace": 0.42, "left": 0.06, "right": 0.94, "top": 0.84, "bottom": 0.16}
    )
    if not records:
        for ax in axes:
            ax.set_axis_off()
        axes[1].text(
            0.5, 0.5, "no generations yet", ha="center", va="center", color=_MUTED, fontsize=11
        )
        return _png(fig)
    recs = sorted(records, key=lambda r: r["generation"])
    g = np.array([r["generation"] for r in recs], dtype=float)

    def col(key: str) -> np.ndarray:
        return np.array([float(r.get(key) or 0.0) for r in recs])

    best, mean, worst = col("best_rating"), col("mean_rating"), col("min_rating")
    calls, cost, secs = (
        np.cumsum(col("calls")),
        np.cumsum(col("cost_usd")),
        np.cumsum(col("seconds")),
    )
    marker = "o" if len(g) <= 30 else None

    ax = axes[0]
    _style(ax)
    ax.fill_between(g, worst, best, color="#c7d7f0", linewidth=0, label="range")
    ax.plot(g, best, color="#1f5fbf", linewidth=1.8, marker=marker, markersize=3.5, label="best")
    ax.plot(g, mean, color="#5a5a5a", linewidth=1.2, linestyle="--", label="mean")
    ax.plot(g, worst, color="#9ab3da", linewidth=1.0, label="worst")
    ax.set_title("Elo rating", fontsize=9, color=_INK, pad=16)
    ax.legend(
        fontsize=7,
        frameon=False,
        loc="lower center",
        bbox_to_anchor=(0.5, 0.99),
        ncols=4,
        handlelength=1.4,
        columnspacing=0.9,
        borderaxespad=0.1,
    )

    ax = axes[1]
    _style(ax)
    ax.plot(g, calls, color="#2a8a57", linewidth=1.8, marker=marker, markersize=3.5)
    ax.set_title("judge calls (cumulative)", fontsize=9, color=_INK)
    ax.set_ylim(bottom=0)
    cx = ax.twinx()
    cx.plot(g, cost, color="#c0392b", linewidth=1.2, linestyle="--")
    cx.set_ylim(bottom=0, top=max(float(cost.max()) * 1.1, 0.01))
    cx.tick_params(labelsize=8, colors="#c0392b", length=3)
    cx.yaxis.set_major_formatter("${x:,.2f}")
    for side in ("top", "left", "bottom"):
        cx.spines[side].set_visible(False)
    cx.spines["right"].set_color(_MUTED)
    ax.text(0.02, 0.96, "calls", transform=ax.transAxes, fontsize=7, color="#2a8a57", va="top")
    ax.text(
        0.02, 0.86, "cost (right)", transform=ax.transAxes, fontsize=7, color="#c0392b", va="top"
    )

    ax = axes[2]
    _style(ax)
    minutes = secs.max() >= 120
    ax.plot(
        g,
        secs / 60 if minutes else secs,
        color="#7d4cb3",
        linewidth=1.8,
        marker=marker,
        markersize=3.5,
    )
    ax.set_title(f"time (cumulative, {'min' if minutes else 's'})", fontsize=9, color=_INK)
    ax.set_ylim(bottom=0)

    for ax in axes:
        ax.set_xlabel("generation", fontsize=8, color=_INK)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True, nbins=8))
    return _png(fig)
