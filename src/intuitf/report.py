"""The HTML report of a run: one self-contained page to open in any browser.

:func:`build_report` reads whatever the run folder holds (see :mod:`intuitf.session.rundir`
for the layout), :func:`report_html` turns it into HTML, and the page is written next to it as
``report.html``. Images are inlined as base64 ``data:`` URIs and exports as downloadable
``data:`` links, so the page has no external references and can be mailed or archived alone.
Missing pieces (a run stopped early, no exports yet) are left out, never an error.
"""

from __future__ import annotations

import base64
import html
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from intuitf.errors import SessionError
from intuitf.session.rundir import RunDirectory, latest_generations
from intuitf.tf.export import EXPORT_FORMATS

REPORT_NAME = "report.html"


@dataclass
class BestEntry:
    """One of the best TFs of a run, with the files written for it."""

    rank: int
    rating: float | None = None
    image: bytes | None = None  # rendering (PNG)
    plot: bytes | None = None  # TF plot (PNG)
    tf: dict | None = None  # GaussianTF.to_dict()
    tf_json: bytes | None = None
    exports: list[tuple[str, str, bytes]] = field(default_factory=list)  # (format, name, data)


@dataclass
class RunContents:
    """Everything the report shows, read from a run folder."""

    name: str
    run: dict = field(default_factory=dict)
    generations: list[dict] = field(default_factory=list)  # journal entries, one per generation
    end: dict | None = None
    best: list[BestEntry] = field(default_factory=list)
    evolution: bytes | None = None
    sheets: list[tuple[int, bytes]] = field(default_factory=list)


# -- reading the run folder -----------------------------------------------------------------
def _read_bytes(path: Path) -> bytes | None:
    try:
        return path.read_bytes() if path.is_file() else None
    except OSError:
        return None


def _read_json(path: Path) -> Any:
    data = _read_bytes(path)
    if data is None:
        return None
    try:
        return json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError):
        return None


def _gaussian_key(tf: dict | None) -> tuple | None:
    """The Gaussians' parameters, to find a best TF among the journal's candidates."""
    try:
        return tuple(
            (
                round(g["mean"], 9),
                round(g["width"], 9),
                round(g["height"], 9),
                *(round(c, 9) for c in g["color"]),
            )
            for g in sorted(tf["gaussians"], key=lambda g: (g["mean"], g["width"]))
        )
    except (KeyError, TypeError, ValueError):
        return None


def collect_run(run_dir: str | Path) -> RunContents:
    """Read what the report needs from ``run_dir``; missing or unreadable files are skipped."""
    root = Path(run_dir)
    if not root.is_dir():
        raise SessionError(
            f"{root} is not a run folder (it does not exist or is not a directory).",
            "Give the folder that `intuitf optimize` wrote (the one holding run.json).",
        )
    rd = RunDirectory(root)
    run = _read_json(rd.run_json)
    contents = RunContents(name=root.resolve().name, run=run if isinstance(run, dict) else {})

    journal = rd.read_journal()
    contents.generations = latest_generations(journal)
    ends = [e for e in journal if e.get("type") == "end"]
    contents.end = ends[-1] if ends else None

    summary = _read_json(rd.best_summary)
    if isinstance(summary, dict):  # {"best": [...], "notes": [...]}; older runs: the list only
        summary = summary.get("best")
    rating_of = {}
    if isinstance(summary, list):
        rating_of = {
            int(s["rank"]): s.get("rating")
            for s in summary
            if isinstance(s, dict) and isinstance(s.get("rank"), int)
        }
    ratings_by_tf: dict[tuple, float] = {}
    for e in contents.generations:
        for c in e.get("candidates", []):
            key = _gaussian_key(c.get("tf")) if isinstance(c, dict) else None
            if key is not None and isinstance(c.get("rating"), int | float):
                ratings_by_tf[key] = float(c["rating"])

    for rank in rd.best_ranks():
        stem = rd.best_stem(rank)
        entry = BestEntry(rank=rank)
        entry.image = _read_bytes(stem.with_name(stem.name + ".png"))
        entry.plot = _read_bytes(stem.with_name(stem.name + ".tf.png"))
        entry.tf_json = _read_bytes(stem.with_name(stem.name + ".tf.json"))
        tf = _read_json(stem.with_name(stem.name + ".tf.json"))
        entry.tf = tf if isinstance(tf, dict) else None
        rating = rating_of.get(rank)
        if rating is None:
            rating = ratings_by_tf.get(_gaussian_key(entry.tf))
        entry.rating = float(rating) if isinstance(rating, int | float) else None
        for fmt, suffix in EXPORT_FORMATS.items():
            data = _read_bytes(stem.with_name(stem.name + suffix))
            if data is not None:
                entry.exports.append((fmt, stem.name + suffix, data))
        contents.best.append(entry)

    contents.evolution = _read_bytes(root / "evolution.png")
    for p in sorted((root / "generations").glob("gen*.png")):
        m = re.fullmatch(r"gen(\d+)\.png", p.name)
        data = _read_bytes(p)
        if m and data is not None:
            contents.sheets.append((int(m.group(1)), data))
    return contents


# -- HTML -----------------------------------------------------------------------------------
def _short(value: Any) -> Any:
    """``value`` with every float rounded to 6 significant digits, for display."""
    if isinstance(value, float):
        return float(f"{value:.6g}")
    if isinstance(value, dict):
        return {k: _short(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_short(v) for v in value]
    return value


def _e(value: Any) -> str:
    """Any value as escaped text (nested values as compact JSON)."""
    if value is None:
        return "—"
    if isinstance(value, float):
        return html.escape(f"{value:.6g}")
    if isinstance(value, dict | list | tuple):
        return html.escape(json.dumps(_short(value), ensure_ascii=False, default=str))
    return html.escape(str(value))


def _img(data: bytes | None, alt: str, cls: str = "") -> str:
    if not data:
        return ""
    b64 = base64.b64encode(data).decode("ascii")
    return f'<img class="{cls}" alt="{html.escape(alt, quote=True)}" src="data:image/png;base64,{b64}">'


def _download(name: str, data: bytes, label: str) -> str:
    b64 = base64.b64encode(data).decode("ascii")
    return (
        f'<a class="dl" download="{html.escape(name, quote=True)}" '
        f'href="data:application/octet-stream;base64,{b64}">{html.escape(label)}</a>'
    )


def _table(rows: list[tuple[str, Any]]) -> str:
    body = "".join(f"<tr><th>{html.escape(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows)
    return f'<table class="kv">{body}</table>'


_EXPORT_LABELS = {
    "paraview": "ParaView",
    "slicer": "3D Slicer",
    "vtk": "VTK Python",
    "1dt": "ImageVis3D",
}


def _swatch(color: Any) -> str:
    try:
        r, g, b = (max(0, min(255, round(float(c) * 255))) for c in color)
    except (TypeError, ValueError):
        return ""
    return f'<span class="sw" style="background:rgb({r},{g},{b})"></span>'


def _gaussian_table(tf: dict) -> str:
    gs = tf.get("gaussians") if isinstance(tf, dict) else None
    if not isinstance(gs, list) or not gs:
        return ""
    vr = tf.get("value_range")
    rows = []
    for g in sorted((g for g in gs if isinstance(g, dict)), key=lambda g: g.get("mean", 0)):
        mean, width = g.get("mean"), g.get("width")
        if isinstance(vr, list) and len(vr) == 2 and isinstance(mean, int | float):
            lo, hi = vr
            where = f"{lo + mean * (hi - lo):.4g} ± {width * (hi - lo):.3g}"
        else:
            where = f"{_e(mean)} ± {_e(width)}"
        rows.append(
            f"<tr><td>{_swatch(g.get('color'))}</td><td>{html.escape(where)}</td>"
            f"<td>{_e(g.get('height'))}</td></tr>"
        )
    return (
        '<table class="gs"><tr><th></th><th>value ± width</th><th>opacity/voxel</th></tr>'
        + "".join(rows)
        + "</table>"
    )


def _match_stats(c: RunContents):
    from intuitf.evaluator.tournament import MatchStats

    return MatchStats.from_journal(c.generations)


def _costs(c: RunContents) -> list[tuple[str, Any]]:
    def total(key: str) -> float:
        return sum(float(e.get(key) or 0) for e in c.generations)

    # The end entry's cost comes from the verdict store: every paid request, also those of an
    # interrupted generation, which no generation entry holds.
    end_cost = c.end.get("cost") if c.end and isinstance(c.end.get("cost"), dict) else {}

    def paid(key: str, end_key: str | None = None) -> float:
        try:
            at_end = float(end_cost.get(end_key or key) or 0)
        except (TypeError, ValueError):
            at_end = 0.0
        return max(total(key), at_end)

    rows: list[tuple[str, Any]] = [
        ("generations", len(c.generations)),
        ("judge calls", int(paid("calls"))),
        ("answered from cache", int(total("cached_calls"))),
        ("input tokens", int(paid("input_tokens"))),
        ("output tokens", int(paid("output_tokens"))),
        ("cost (USD)", f"${paid('cost_usd', 'usd'):.4f}"),
        ("time", f"{total('seconds'):.1f} s"),
    ]
    stats = _match_stats(c)
    if stats.matches:
        rows.append(
            (
                "matches",
                f"{stats.matches}: {stats.decided} decided, {stats.undecided} undecided, "
                f"{stats.retried} asked again",
            )
        )
    judges = c.run.get("judges")
    if isinstance(judges, list) and len(judges) > 1:
        for j in judges:
            if isinstance(j, dict):
                who = j.get("evaluator") or j.get("judge") or "?"
                if j.get("base_url"):
                    who = f"{who} at {j['base_url']}"
                rows.append((f"judge from gen {int(j.get('from_generation', 0)) + 1}", who))
    if c.end:
        rows.append(
            ("ended", f"{c.end.get('reason', '?')}: {c.end.get('message', '')}".strip(": "))
        )
    return rows


_CSS = """
:root { --ink:#1d1d22; --muted:#6b6b76; --line:#e3e3e8; --card:#fff; --bg:#f4f4f7; --acc:#1f5fbf; }
* { box-sizing: border-box; }
body { margin:0; background:var(--bg); color:var(--ink);
  font:14px/1.45 system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif; }
header { background:#18181d; color:#f3f3f6; padding:22px 32px; }
header h1 { margin:0 0 4px; font-size:22px; font-weight:600; }
header .intent { color:#c9c9d3; font-size:15px; white-space:pre-wrap; }
main { max-width:1240px; margin:0 auto; padding:20px 24px 48px; }
section { background:var(--card); border:1px solid var(--line); border-radius:10px;
  padding:16px 20px; margin:18px 0; }
h2 { font-size:16px; margin:0 0 12px; }
.grid { display:grid; grid-template-columns:repeat(auto-fit, minmax(300px, 1fr)); gap:16px; }
table { border-collapse:collapse; }
.kv th { text-align:left; color:var(--muted); font-weight:500; padding:3px 16px 3px 0;
  vertical-align:top; white-space:nowrap; }
.kv td { padding:3px 0; word-break:break-word; }
.best { width:100%; }
.best > tbody > tr > td, .best > thead > tr > th { border-top:1px solid var(--line); padding:12px 10px;
  vertical-align:top; text-align:left; }
.best > thead > tr > th { color:var(--muted); font-weight:500; border-top:none; }
.rank { font-size:20px; font-weight:600; }
.rating { font-variant-numeric:tabular-nums; }
img.render { width:220px; height:auto; border-radius:6px; background:#000; display:block; }
img.plot { width:420px; max-width:100%; height:auto; display:block; }
img.wide { width:100%; height:auto; display:block; }
.gs { margin-top:6px; font-size:12px; } .gs td, .gs th { padding:1px 8px 1px 0; text-align:left; }
.gs th { color:var(--muted); font-weight:500; }
.sw { display:inline-block; width:12px; height:12px; border-radius:3px; border:1px solid #0003;
  vertical-align:-2px; }
a.dl { display:inline-block; margin:0 6px 6px 0; padding:3px 10px; border:1px solid var(--acc);
  border-radius:14px; color:var(--acc); text-decoration:none; font-size:12px; }
a.dl:hover { background:var(--acc); color:#fff; }
details { margin:8px 0; } summary { cursor:pointer; color:var(--ink); padding:4px 0; }
.note { color:var(--muted); font-size:12px; }
.warn { background:#fff4d6; border:1px solid #e6c65c; border-radius:6px; padding:8px 12px; }
"""


def report_html(c: RunContents) -> str:
    """The report page for the run ``c`` (all user text escaped, every asset inlined)."""
    run = c.run
    intent = run.get("intent") if isinstance(run.get("intent"), dict) else {}
    settings = run.get("settings") if isinstance(run.get("settings"), dict) else {}
    volume = run.get("volume") if isinstance(run.get("volume"), dict) else {}
    stage_of = {e["generation"]: e.get("stage") for e in c.generations}

    intent_text = intent.get("text") or ""
    head = f"<h1>intuitf run · {html.escape(c.name)}</h1>"
    if intent_text:
        head += f'<div class="intent">“{html.escape(str(intent_text))}”</div>'
    # How the intent was read, right under it: what was asked, then what intuitf made of it
    # (below the Run grid it read as a footnote to the settings).
    understood = run.get("understood")
    if isinstance(understood, list) and understood:
        items = "".join(f"<li>{html.escape(str(line))}</li>" for line in understood)
        head += f'<h3 class="note">Understood</h3><ul class="understood">{items}</ul>'

    key_settings = ["evaluator", "population", "generations", "seed"]
    # Older and newer run records keep the evaluator in settings or as "judge" beside them.
    settings = {"evaluator": run.get("judge"), **settings} if "judge" in run else settings
    setting_rows = [(k, settings.get(k)) for k in key_settings if settings.get(k) is not None]
    setting_rows += [(k, v) for k, v in settings.items() if k not in key_settings]
    # Flags that are off and empty fields say nothing about the intent: leave them out.
    intent_rows = [
        (k, v) for k, v in intent.items() if k != "text" and v not in (None, False, [], "")
    ]
    volume_rows = [
        ("name", volume.get("name")),
        ("source", volume.get("source")),
        ("size (x, y, z)", " × ".join(str(v) for v in volume.get("dims_xyz", [])) or None),
        ("type", volume.get("dtype")),
        ("value range", volume.get("value_range")),
        ("spacing", volume.get("spacing_xyz")),
    ]
    volume_rows = [(k, v) for k, v in volume_rows if v is not None]
    notes = volume.get("notes")
    volume_rows += [("note", n) for n in notes] if isinstance(notes, list) else []
    parts = [
        '<section><h2>Run</h2><div class="grid">',
        f"<div><h3 class='note'>Volume</h3>{_table(volume_rows)}</div>" if volume_rows else "",
        f"<div><h3 class='note'>Intent</h3>{_table(intent_rows)}</div>" if intent_rows else "",
        f"<div><h3 class='note'>Settings</h3>{_table(setting_rows)}</div>" if setting_rows else "",
        f"<div><h3 class='note'>Cost</h3>{_table(_costs(c))}</div>",
        "</div>",
    ]
    warning = _match_stats(c).warning
    if warning:
        parts.append(f'<p class="warn"><strong>Warning:</strong> {html.escape(warning)}</p>')
    from intuitf.session.outputs import indistinct_note

    indistinct = indistinct_note(c.generations)
    if indistinct:
        parts.append(f'<p class="warn indistinct">{html.escape(indistinct)}</p>')
    if run.get("created"):
        parts.append(f'<p class="note">Started {_e(run.get("created"))}.</p>')
    if isinstance(run.get("versions"), dict) and run["versions"]:
        versions = ", ".join(f"{k} {v}" for k, v in run["versions"].items())
        parts.append(f'<p class="note">Versions: {html.escape(versions)}.</p>')
    parts.append("</section>")

    if c.best:
        rows = []
        for b in c.best:
            links = [
                _download(name, data, _EXPORT_LABELS.get(fmt, fmt)) for fmt, name, data in b.exports
            ]
            if b.tf_json:
                links.insert(0, _download(f"rank{b.rank:02d}.tf.json", b.tf_json, "intuitf JSON"))
            rating = f"{b.rating:.0f}" if b.rating is not None else "—"
            rows.append(
                "<tr>"
                f'<td class="rank">#{b.rank}<div class="rating note">rating {rating}</div></td>'
                f"<td>{_img(b.image, f'rendering of rank {b.rank}', 'render')}</td>"
                f"<td>{_img(b.plot, f'transfer function of rank {b.rank}', 'plot')}"
                f"{_gaussian_table(b.tf) if b.tf else ''}</td>"
                f"<td>{''.join(links) or '—'}</td>"
                "</tr>"
            )
        parts.append(
            "<section><h2>Best transfer functions</h2>"
            '<table class="best"><thead><tr><th>rank</th><th>rendering</th>'
            "<th>transfer function</th><th>downloads</th></tr></thead><tbody>"
            + "".join(rows)
            + "</tbody></table>"
            '<p class="note">Opacities are per voxel. In ParaView set <i>Scalar Opacity Unit Distance</i> '
            "to the voxel size; the VTK file sets it; the 3D Slicer file is converted to Slicer's "
            "unit (1 mm).</p></section>"
        )

    if c.evolution:
        parts.append(
            f"<section><h2>Evolution</h2>{_img(c.evolution, 'evolution of the run', 'wide')}</section>"
        )

    if c.sheets:
        parts.append("<section><h2>Generations</h2>")
        last = c.sheets[-1][0]
        for g, data in c.sheets:
            stage = stage_of.get(g)
            label = f"Generation {g}" + (f" · {html.escape(str(stage))}" if stage else "")
            open_attr = " open" if g == last else ""
            parts.append(
                f"<details{open_attr}><summary>{label}</summary>"
                f"{_img(data, f'renderings of generation {g}', 'wide')}</details>"
            )
        parts.append(
            '<p class="note">Each sheet is ordered by rank; captions give rank, id and rating.</p>'
        )
        parts.append("</section>")

    if not (c.best or c.evolution or c.sheets):
        parts.append('<section><p class="note">This run has no results yet.</p></section>')

    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>intuitf · {html.escape(c.name)}</title><style>{_CSS}</style></head>"
        f"<body><header>{head}</header><main>{''.join(parts)}</main></body></html>\n"
    )


def build_report(run_dir: str | Path) -> Path:
    """Write ``run_dir/report.html`` from what the run folder holds and return its path."""
    from intuitf.session.rundir import atomic_write_bytes

    contents = collect_run(run_dir)
    path = Path(run_dir) / REPORT_NAME
    atomic_write_bytes(path, report_html(contents).encode("utf-8"))
    return path
