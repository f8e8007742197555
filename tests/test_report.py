"""The HTML report: self-contained, escaped, built from whatever a run folder holds."""

from __future__ import annotations

import base64
import functools
import io
import json
import re

import numpy as np
import pytest
from PIL import Image

from intuitf.errors import SessionError
from intuitf.plots import contact_sheet, evolution_plot, tf_plot
from intuitf.report import build_report, collect_run
from intuitf.tf import Gaussian, GaussianTF
from intuitf.tf.export import EXPORT_FORMATS, export_tf

INTENT = 'Show the <b>vessels</b> & "bones" <script>alert(1)</script>'


def png(color, size=(32, 24)) -> bytes:
    buf = io.BytesIO()
    Image.new("RGB", size, color).save(buf, format="PNG")
    return buf.getvalue()


def tf_n(i: int) -> GaussianTF:
    return GaussianTF(
        (
            Gaussian(0.3 + 0.01 * i, 0.05, 0.2, (1.0, 0.2, 0.2)),
            Gaussian(0.8, 0.04, 0.6, (1.0, 1.0, 0.9)),
        ),
        value_range=(0.0, 255.0),
    )


@functools.cache
def plot_pngs() -> tuple[bytes, bytes, bytes]:
    """The TF plots and the evolution plot, made once for all tests (plots take a while)."""
    records = [
        {"generation": g, "best_rating": 1500 + g, "mean_rating": 1500, "min_rating": 1499,
         "calls": 10, "cost_usd": 0.25, "seconds": 3.0}
        for g in range(3)
    ]  # fmt: skip
    return (
        tf_plot(tf_n(0), size=(320, 120)),
        tf_plot(tf_n(1), size=(320, 120)),
        evolution_plot(records, size=(300, 120)),
    )


def make_run(root, *, generations=3, truncated=True, with_best=True):
    """A small run folder in the layout the session writes."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "run.json").write_text(
        json.dumps(
            {
                "volume": {
                    "name": "engine",
                    "source": "engine.nrrd",
                    "dims_xyz": [64, 64, 32],
                    "dtype": "uint8",
                    "value_range": [0.0, 255.0],
                    "mean": 40.0,
                    "spacing_xyz": [1.0, 1.0, 2.0],
                    "notes": [],
                },
                "intent": {"kind": "text", "text": INTENT, "about": "structures"},
                "settings": {"evaluator": "metric", "population": 4, "generations": 3, "seed": 7},
                "versions": {"intuitf": "0.1.0"},
                "created": "2024-05-01T12:00:00",
            }
        )
    )
    lines = [json.dumps({"type": "stage", "generation": 0, "stage": "initialize"})]
    for g in range(generations):
        cands = [
            {
                "id": f"g{g}c{i}",
                "tf": tf_n(i).to_dict(),
                "rating": 1500.0 + 10 * g - 5 * i,
                "rank": i + 1,
                "origin": "init",
                "parents": [],
            }
            for i in range(4)
        ]
        lines.append(
            json.dumps(
                {
                    "type": "generation",
                    "generation": g,
                    "stage": "initialize" if g < 2 else "customize",
                    "candidates": cands,
                    "best_id": f"g{g}c0",
                    "calls": 10,
                    "cached_calls": 2,
                    "input_tokens": 1000,
                    "output_tokens": 100,
                    "cost_usd": 0.25,
                    "seconds": 3.0,
                }
            )
        )
    lines.append(json.dumps({"type": "verdict", "whatever": 1}))  # an unknown type
    lines.append(json.dumps({"type": "end", "reason": "completed", "message": "All done."}))
    text = "\n".join(lines) + "\n"
    if truncated:
        text += '{"type": "generation", "generation": 9, "cand'  # cut short by a crash
    (root / "journal.jsonl").write_text(text)

    sheets = root / "generations"
    sheets.mkdir()
    for g in range(generations):
        sheet = contact_sheet([np.zeros((16, 16, 3), np.uint8)] * 2, [f"#1 g{g}", "#2 x"], thumb=32)
        buf = io.BytesIO()
        Image.fromarray(sheet).save(buf, format="PNG")
        (sheets / f"gen{g:03d}.png").write_bytes(buf.getvalue())
    (root / "evolution.png").write_bytes(plot_pngs()[2])
    if with_best:
        best = root / "best"
        best.mkdir()
        for rank in (1, 2):
            tf = tf_n(rank - 1)
            stem = f"rank{rank:02d}"
            (best / f"{stem}.png").write_bytes(png((200, 40 * rank, 10)))
            (best / f"{stem}.tf.json").write_text(tf.to_json())
            (best / f"{stem}.tf.png").write_bytes(plot_pngs()[rank - 1])
            for fmt, suffix in EXPORT_FORMATS.items():
                if rank == 2 and fmt == "1dt":
                    continue  # a missing export is skipped
                (best / f"{stem}{suffix}").write_text(export_tf(tf, fmt))
    return root


def data_uris(page: str, kind: str) -> list[bytes]:
    return [
        base64.b64decode(m) for m in re.findall(rf'"data:{kind};base64,([A-Za-z0-9+/=]+)"', page)
    ]


def test_report_is_self_contained_and_inlines_everything(tmp_path):
    run = make_run(tmp_path / "run")
    path = build_report(run)
    assert path == run / "report.html"
    page = path.read_text(encoding="utf-8")
    assert page.startswith("<!DOCTYPE html>")
    # No reference leaves the page.
    outside_data = re.sub(r"data:[a-z/+-]+;base64,[A-Za-z0-9+/=]+", "", page)
    assert not re.search(r"(https?:|file:|//[a-z]|@import|url\()", outside_data, re.IGNORECASE)
    for attr in re.findall(r'(?:src|href)="([^"]*)"', page):
        assert attr.startswith("data:")
    images = data_uris(page, "image/png")
    # 2 renderings + 2 TF plots + evolution + 3 generation sheets.
    assert len(images) == 8
    assert (run / "best" / "rank01.png").read_bytes() in images
    assert (run / "evolution.png").read_bytes() in images
    assert (run / "generations" / "gen002.png").read_bytes() in images
    # Exports are downloadable and byte-identical; the missing one is simply absent.
    files = data_uris(page, "application/octet-stream")
    assert (run / "best" / "rank01.vp").read_bytes() in files
    assert (run / "best" / "rank02.paraview.json").read_bytes() in files
    assert 'download="rank01.1dt"' in page and 'download="rank02.1dt"' not in page
    assert 'download="rank01.tf.json"' in page
    assert len(files) == 4 + 3 + 2


def test_report_escapes_user_text_and_shows_settings_and_costs(tmp_path):
    page = build_report(make_run(tmp_path / "run")).read_text(encoding="utf-8")
    assert "<script>" not in page and "<b>vessels</b>" not in page
    assert "&lt;b&gt;vessels&lt;/b&gt; &amp; &quot;bones&quot; &lt;script&gt;" in page
    for text in ("engine", "metric", "seed", "customize", "All done."):
        assert text in page
    assert "$0.7500" in page  # three generations at $0.25
    assert ">30<" in page  # judge calls
    # Ratings come from the journal when best/summary.json is missing: rank 1 is candidate 0.
    assert "rating 1520" in page


def test_collect_run_tolerates_missing_pieces(tmp_path):
    run = make_run(tmp_path / "run", generations=1, truncated=True, with_best=False)
    (run / "evolution.png").unlink()
    c = collect_run(run)
    assert [e["generation"] for e in c.generations] == [0]
    assert c.best == [] and c.evolution is None and len(c.sheets) == 1
    assert c.end and c.end["reason"] == "completed"
    empty = tmp_path / "empty"
    empty.mkdir()
    page = build_report(empty).read_text()
    assert "no results yet" in page


def test_summary_json_ratings_win(tmp_path):
    run = make_run(tmp_path / "run")
    (run / "best" / "summary.json").write_text(
        json.dumps([{"rank": 1, "rating": 1642.4, "tf": "x"}])
    )
    assert collect_run(run).best[0].rating == pytest.approx(1642.4)


def test_missing_run_folder_is_a_clear_error(tmp_path):
    with pytest.raises(SessionError) as info:
        build_report(tmp_path / "nope")
    assert "not a run folder" in info.value.message and info.value.hint
