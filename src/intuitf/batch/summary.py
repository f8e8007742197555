"""What a batch tells at the end: DIR/summary.json, a table, a contact sheet and an HTML report.

Per volume: status, the similarity of its best rendering to the reference picture (colour
distribution of the rendered materials, see :meth:`Reference.similarity`), and before the
search (the TF the run started from: the reference TF carried over, or the volume's default), calls, cost, time and how that time split between rendering
and waiting for the judge. A volume is *flagged* when it did not finish or its best stays far
from the reference (similarity below ``flag_below``): those are the scans to look at.
"""

from __future__ import annotations

import html
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

#: Similarity under which a volume's best counts as far from the reference look.
DEFAULT_FLAG_BELOW = 0.5


def _num(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def flag_reason(result: dict, flag_below: float) -> str | None:
    """Why a volume needs a look, or None."""
    status = result.get("status")
    if status != "completed":
        return f"not finished ({status})"
    sim = _num(result.get("similarity"))
    if sim is None:
        return "no result rendering"
    if sim < flag_below:
        return f"far from the reference (similarity {sim:.2f} < {flag_below:.2f})"
    return None


def build_summary(
    root: Path,
    items: list,
    results: dict[str, dict],
    *,
    flag_below: float = DEFAULT_FLAG_BELOW,
    reference: str = "",
    ledger: dict | None = None,
    wall_s: float | None = None,
    backend: str = "",
    workers: int | None = None,
) -> dict:
    """The summary of the batch in ``root`` over ``items`` (results read from DIR/results)."""
    from intuitf.batch.runner import _base_result, read_result

    volumes = []
    for it in items:
        res = results.get(it.key) or read_result(root, it.key) or _base_result(it)
        res = dict(res)
        res.setdefault("key", it.key)
        res["label"] = it.label
        reason = flag_reason(res, flag_below)
        res["flagged"] = reason is not None
        res["flag"] = reason
        volumes.append(res)
    done = [v for v in volumes if v.get("status") == "completed"]
    sims = [s for v in done if (s := _num(v.get("similarity"))) is not None]
    totals = {
        "volumes": len(volumes),
        "completed": len(done),
        "flagged": sum(v["flagged"] for v in volumes),
        "failed": sum(v.get("status") == "failed" for v in volumes),
        "calls": sum(int(v.get("calls") or 0) for v in volumes),
        "cost_usd": sum(float(v.get("cost_usd") or 0.0) for v in volumes),
        "volume_seconds": sum(float(v.get("seconds") or 0.0) for v in volumes),
        "render_s": sum(float(v.get("render_s") or 0.0) for v in volumes),
        "judge_s": sum(float(v.get("judge_s") or 0.0) for v in volumes),
        "open_s": sum(float(v.get("open_s") or 0.0) for v in volumes),
        "outputs_s": sum(float(v.get("outputs_s") or 0.0) for v in volumes),
        "mean_similarity": float(np.mean(sims)) if sims else None,
        "matches": sum(int(v.get("matches") or 0) for v in volumes),
        "undecided": sum(int(v.get("undecided") or 0) for v in volumes),
    }
    totals["undecided_share"] = (
        totals["undecided"] / totals["matches"] if totals["matches"] else 0.0
    )
    if wall_s:
        totals["wall_s"] = wall_s
        totals["volumes_per_hour"] = 3600.0 * len(done) / wall_s if done else 0.0
    return {
        "reference": reference,
        "flag_below": flag_below,
        "backend": backend,
        "workers": workers,
        "budget": ledger,
        "totals": totals,
        "volumes": volumes,
        "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def write_summary(root: Path, summary: dict) -> dict[str, Path]:
    """Write summary.json, contact_sheet.png and report.html into ``root``; their paths."""
    from intuitf.session.rundir import atomic_write_bytes, atomic_write_json

    paths = {"summary": root / "summary.json"}
    atomic_write_json(paths["summary"], summary)
    sheet = contact_sheet(root, summary)
    if sheet is not None:
        from intuitf.imageio import png_bytes

        paths["contact_sheet"] = root / "contact_sheet.png"
        atomic_write_bytes(paths["contact_sheet"], png_bytes(sheet))
    paths["report"] = root / "report.html"
    atomic_write_bytes(paths["report"], report_html(summary, root, sheet=sheet).encode("utf-8"))
    return paths


def contact_sheet(root: Path, summary: dict, thumb: int = 320) -> np.ndarray | None:
    """The reference, then every volume's best, captioned (flagged ones marked '!').

    Tiles are ``thumb`` pixels, large enough to judge a look by; a caption starts with the
    similarity, so a long volume name is what gets shortened, never the figure.
    """
    from intuitf.imageio import load_image
    from intuitf.plots import contact_sheet as sheet

    images, captions = [], []
    ref = root / "reference" / "reference.png"
    if ref.exists():
        images.append(load_image(ref))
        captions.append("REFERENCE")
    for v in summary["volumes"]:
        png = v.get("best_png")
        img = None
        if png and (root / png).exists():
            try:
                img = load_image(root / png)
            except Exception:  # noqa: BLE001 - an unreadable picture is shown as missing
                img = None
        if img is None:
            img = np.full((thumb, thumb, 3), 40, np.uint8)
        sim = _num(v.get("similarity"))
        mark = "! " if v.get("flagged") else ""
        cap = (
            f"{mark}{sim:.2f} {v['key']}"
            if sim is not None
            else f"{mark}{v.get('status')} {v['key']}"
        )
        images.append(img)
        captions.append(cap)
    if not images:
        return None
    return sheet(images, captions, columns=min(4, max(2, len(images))), thumb=thumb)


def _fmt(v: Any, spec: str, empty: str = "–") -> str:
    f = _num(v)
    return empty if f is None else format(f, spec)


def _data_uri(path: Path | None, size: int | None = None) -> str | None:
    """A picture file as a PNG data URI (scaled to fit ``size``), or None if unreadable."""
    if path is None or not path.exists():
        return None
    try:
        from PIL import Image

        from intuitf.imageio import load_image, png_bytes

        img = load_image(path)
        if size is not None and max(img.shape[:2]) > size:
            pic = Image.fromarray(img)
            pic.thumbnail((size, size), Image.Resampling.LANCZOS)
            img = np.asarray(pic)
        return _png_uri(png_bytes(img))
    except Exception:  # noqa: BLE001 - a picture that cannot be read is left out
        return None


def _png_uri(data: bytes) -> str:
    import base64

    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _undecided_cell(v: dict) -> str:
    n, m = int(v.get("undecided") or 0), int(v.get("matches") or 0)
    return f"{n} of {m} ({100 * n / m:.0f} %)" if m else "–"


def _indistinct_note(v: dict) -> str:
    """A sentence when the judge could not tell a generation's candidates apart."""
    gens = v.get("indistinct_generations") or []
    if not gens:
        return ""
    which = ", ".join(str(int(g)) for g in gens)
    return f"generation {which}: the judge could not tell the candidates apart"


def report_html(summary: dict, root: Path | None = None, sheet: np.ndarray | None = None) -> str:
    """A self-contained page: the pictures (reference, each volume's best, the contact sheet)
    are inside it, read from the batch folder ``root``; links go to each run's own report."""
    from intuitf.evaluator.matches import UNDECIDED_WARNING
    from intuitf.imageio import png_bytes

    t = summary["totals"]
    rows = []
    for v in summary["volumes"]:
        flagged = v.get("flagged")
        best = root / v["best_png"] if root is not None and v.get("best_png") else None
        uri = _data_uri(best, 256)
        img = f'<img src="{uri}" width="128" height="128" alt="best">' if uri else ""
        report = (
            f'<a href="runs/{html.escape(v["key"])}/report.html">run</a>'
            if v.get("run_dir")
            else ""
        )
        rows.append(
            f'<tr class="{"flag" if flagged else ""}"><td>{img}</td>'
            f"<td><b>{html.escape(str(v['key']))}</b><br><small>{html.escape(str(v.get('source', '')))}</small></td>"
            f"<td>{html.escape(str(v.get('status')))}</td>"
            f"<td>{_fmt(v.get('similarity'), '.3f')}</td>"
            f"<td>{_fmt(v.get('start_similarity'), '.3f')}</td>"
            f"<td>{int(v.get('calls') or 0)}</td>"
            f"<td>{_undecided_cell(v)}</td>"
            f"<td>${_fmt(v.get('cost_usd'), '.4f', '0')}</td>"
            f"<td>{_fmt(v.get('seconds'), '.1f')}</td>"
            f"<td>{_fmt(v.get('render_s'), '.1f')} / {_fmt(v.get('judge_s'), '.1f')}</td>"
            f"<td>{html.escape(v.get('flag') or '')}<br><small>{html.escape(str(v.get('message') or ''))[:300]}"
            f"{'<br>' + html.escape(_indistinct_note(v)) if _indistinct_note(v) else ''}</small></td>"
            f"<td>{report}</td></tr>"
        )
    budget = summary.get("budget") or {}
    limit = []
    if budget.get("max_calls") is not None:
        limit.append(f"{budget['max_calls']} calls")
    if budget.get("max_usd") is not None:
        limit.append(f"${budget['max_usd']:.2f}")
    budget_line = (
        f"Budget: {' and '.join(limit)}; counted {budget.get('paid_calls', 0) + budget.get('in_flight', 0) + budget.get('lost', 0)} calls "
        f"(${budget.get('paid_usd', 0.0):.4f} paid)."
        if limit
        else "No batch budget."
    )
    mean = t.get("mean_similarity")
    ref = _data_uri(root / "reference" / "reference.png", 384) if root is not None else None
    ref_img = f'<img src="{ref}" width="192" height="192" alt="reference"><br>' if ref else ""
    sheet_img = (
        f'<details><summary>Contact sheet</summary><img src="{_png_uri(png_bytes(sheet))}" '
        'style="max-width: 100%" alt="contact sheet"></details>'
        if sheet is not None
        else ""
    )
    share = float(t.get("undecided_share") or 0.0)
    undecided_line = (
        f"{t.get('undecided', 0)} of {t.get('matches', 0)} matches ({100 * share:.0f} %) "
        "stayed undecided (no usable answer from the model even when asked again)."
    )
    if share > UNDECIDED_WARNING:
        undecided_line = f"<b>Warning:</b> {undecided_line} The rankings rest on less evidence."
    return f"""<!doctype html>
<html><head><meta charset="utf-8"><title>intuitf batch</title>
<style>
body {{ font-family: system-ui, sans-serif; margin: 1.5em; background: #fafafa; color: #18181b; }}
table {{ border-collapse: collapse; width: 100%; }}
td, th {{ border-bottom: 1px solid #ddd; padding: 4px 8px; text-align: left; vertical-align: middle; }}
tr.flag {{ background: #fee2e2; }}
img {{ background: #000; }}
small {{ color: #52525b; }}
</style></head><body>
<h1>intuitf batch</h1>
<p>{ref_img}
Reference: {html.escape(str(summary.get("reference", "")))}</p>
<p>{t["volumes"]} volumes: {t["completed"]} completed, {t["flagged"]} flagged (not finished, or
similarity below {summary["flag_below"]:.2f}), {t["failed"]} failed to load or run.
Mean similarity of the completed: {_fmt(mean, ".3f")}. {t["calls"]} model calls,
${t["cost_usd"]:.4f}. {html.escape(budget_line)}</p>
<p>{undecided_line}</p>
{sheet_img}
<table><tr><th>best</th><th>volume</th><th>status</th><th>similarity</th><th>before search</th>
<th>calls</th><th>undecided</th><th>cost</th><th>time (s)</th><th>render / judge (s)</th><th>flag</th><th></th></tr>
{"".join(rows)}
</table>
<p><small>Similarity: colour distribution of the rendered materials against the reference picture
(intersection of CIELAB histograms minus mean-colour distance / 100; 1 = same colours in the
same shares). "Before search": the TF the run started from (the reference TF carried to the volume, or the
volume's default TF), before any search.</small></p>
</body></html>
"""


def summary_table(summary: dict):
    """A Rich table of the batch, one row per volume (flagged rows in red, marked "!")."""
    from rich.table import Table

    table = Table(title="Batch", show_lines=False, pad_edge=False)
    table.add_column("volume", overflow="fold")
    table.add_column("status")
    table.add_column("sim", justify="right")
    table.add_column("start", justify="right")
    table.add_column("calls", justify="right")
    table.add_column("undecided", justify="right")
    table.add_column("$", justify="right")
    table.add_column("time s", justify="right")
    table.add_column("render/judge s", justify="right")
    for v in summary["volumes"]:
        flagged = v.get("flagged")
        status = str(v.get("status")) + (" (before)" if v.get("skipped") else "")
        table.add_row(
            ("! " if flagged else "") + str(v["key"]),
            status,
            _fmt(v.get("similarity"), ".3f"),
            _fmt(v.get("start_similarity"), ".3f"),
            str(int(v.get("calls") or 0)),
            _undecided_cell(v),
            _fmt(v.get("cost_usd"), ".4f", "0"),
            _fmt(v.get("seconds"), ".1f"),
            f"{_fmt(v.get('render_s'), '.1f')}/{_fmt(v.get('judge_s'), '.1f')}",
            style="red" if flagged else None,
        )
    return table
