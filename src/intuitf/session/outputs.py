"""What a run leaves behind for people: best renderings, TFs, plots, exports and a report."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from intuitf.session.rundir import atomic_write_bytes, atomic_write_json

if TYPE_CHECKING:
    from intuitf.session.session import Session


def evolution_records(generations: list[dict]) -> list[dict]:
    """Per-generation figures for the evolution plot, from the journal's generation entries
    (:meth:`RunDirectory.generations`)."""
    out = []
    for e in generations:
        ratings = [c["rating"] for c in e.get("candidates", [])] or [0.0]
        out.append(
            {
                "generation": e["generation"],
                "best_rating": max(ratings),
                "mean_rating": sum(ratings) / len(ratings),
                "min_rating": min(ratings),
                "calls": e.get("calls", 0),
                "cost_usd": e.get("cost_usd", 0.0),
                "seconds": e.get("seconds", 0.0),
            }
        )
    return out


def indistinct_generations(generations: list[dict]) -> list[int]:
    """The generations whose candidates the judge could not tell apart (every decided match a
    tie), from the journal's generation entries (:meth:`RunDirectory.generations`)."""
    out = []
    for e in generations:
        stats = e.get("match_stats") if isinstance(e.get("match_stats"), dict) else {}
        if e.get("indistinct") or (stats or {}).get("indistinct"):
            out.append(int(e["generation"]))
    return out


def indistinct_note(generations: list[dict]) -> str:
    """A plain sentence naming the generations whose candidates could not be told apart (""
    when there are none): said at the end of a run, in summary.json, the report and the web."""
    gens = indistinct_generations(generations)
    if not gens:
        return ""
    which = ", ".join(str(g) for g in gens)
    word = "generation" if len(gens) == 1 else "generations"
    return (
        f"In {word} {which} the judge could not tell the candidates apart (every match a tie): "
        "their ranking says nothing about the words."
    )


def write_run_outputs(session: Session) -> None:
    """Write best/, evolution.png and report.html into the session's run folder."""
    from intuitf.imageio import png_bytes, render_record
    from intuitf.plots import evolution_plot, tf_plot
    from intuitf.report import build_report
    from intuitf.tf.export import EXPORT_FORMATS, export_tf

    rd = session.run_dir
    assert rd is not None
    counts, _ = session.volume.histogram()
    best = session.best(session.settings.top_k)
    summary = []
    unit = min(session.volume.spacing)  # heights are opacity per voxel
    for rank, (tf, rating) in enumerate(best, start=1):
        tf = replace(tf.unfreeze(), value_range=session.volume.value_range, name=f"rank{rank:02d}")
        stem = rd.best_stem(rank)
        image = session.render(tf)
        record = render_record(session.camera, (image.shape[1], image.shape[0]),
                               session.volume.name, shading=session.settings.shading)  # fmt: skip
        atomic_write_bytes(stem.with_suffix(".png"), png_bytes(image, record))
        atomic_write_bytes(stem.with_name(stem.name + ".tf.json"), tf.to_json().encode())
        atomic_write_bytes(stem.with_name(stem.name + ".tf.png"), tf_plot(tf, counts))
        for fmt, suffix in EXPORT_FORMATS.items():
            atomic_write_bytes(
                stem.with_name(stem.name + suffix), export_tf(tf, fmt, unit_distance=unit).encode()
            )
        tf_file = rd.best_file(rank, ".tf.json").relative_to(rd.root).as_posix()
        summary.append({"rank": rank, "rating": rating, "tf": tf_file})
    generations = rd.generations()
    atomic_write_json(
        rd.best_summary,
        {
            "best": summary,
            "indistinct_generations": indistinct_generations(generations),
            "notes": [n for n in (indistinct_note(generations),) if n],
        },
    )
    records = evolution_records(generations)
    if records:
        atomic_write_bytes(rd.root / "evolution.png", evolution_plot(records))
    build_report(rd.root)
