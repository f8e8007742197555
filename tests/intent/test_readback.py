"""How an intent was read is said in lines a person can check."""

from __future__ import annotations

import json

import numpy as np

from intuitf.evaluator.types import Intent
from intuitf.intent.readback import read_back
from intuitf.render import Camera
from intuitf.session import RunSettings, Session
from intuitf.volume import phantom


def test_words_are_read_back_with_where_they_landed_and_what_was_not_understood():
    vol = phantom(48)
    lines = read_back(Intent(kind="text", text="opaque ivory bone, faint red skin, a gizmo"), vol)
    bone = next(line for line in lines if line.startswith('"bone"'))
    skin = next(line for line in lines if line.startswith('"skin"'))
    assert "ivory, opaque" in bone and "values around" in bone
    assert "red, faint" in skin
    # Skin colours the body under its edge too, and says how far.
    assert "and the body under it, values up to" in skin
    assert "up to" not in bone
    assert lines[-1] == "not understood: gizmo"
    # Words that name nothing the volume has say so, rather than nothing.
    assert read_back(Intent(kind="text", text="make it nice"), vol) == [
        "no material or part named: the colours are left to the search"
    ]
    assert read_back(Intent(kind="none"), vol) == []


def test_a_sketch_is_read_back_stroke_by_stroke():
    from tests.intent.test_strokes import sketch_over, two_blocks

    vol, cam = two_blocks(), Camera(azimuth=0.0, elevation=0.0)
    lines = read_back(Intent(kind="sketch", sketch=sketch_over(vol, cam), base=None), vol, cam)
    assert len(lines) == 2
    red = next(line for line in lines if line.startswith("red stroke"))
    blue = next(line for line in lines if line.startswith("blue stroke"))
    # The blocks hold 0.4 and 0.8 (value range 0..1): each stroke on its own block's value.
    assert abs(float(red.split("values around ")[1].split(";")[0]) - 0.4) < 0.05
    assert abs(float(blue.split("values around ")[1].split(";")[0]) - 0.8) < 0.05
    # Nothing drawn on the object: said so.
    empty = np.zeros((64, 64, 4), np.uint8)
    empty[:3, :3] = (255, 0, 0, 255)
    assert read_back(Intent(kind="sketch", sketch=empty), vol, cam) == [
        "no stroke lies on the object: the sketch asks for nothing here"
    ]


def test_a_run_keeps_how_its_words_were_read(tmp_path):
    vol = phantom(32)
    settings = RunSettings(population=4, generations=1, image_size=32, output_size=32, seed=0)
    intent = Intent(kind="text", text="red bone and a gizmo")
    sess = Session.create(vol, intent=intent, settings=settings, run_dir=tmp_path / "run")
    assert sess.understood[0].startswith('"bone": red')
    assert sess.understood[-1] == "not understood: gizmo"
    sess.step()
    sess.close()
    record = json.loads((tmp_path / "run" / "run.json").read_text())
    assert record["understood"] == sess.understood
    # The report says it right under the words, before the run's settings.
    from intuitf.report import build_report

    page = build_report(tmp_path / "run").read_text()
    said = page.index("“red bone and a gizmo”")
    assert said < page.index('<ul class="understood">') < page.index("<h2>Run</h2>")
    assert "<li>not understood: gizmo</li>" in page
    again = Session.resume(tmp_path / "run", vol)
    assert again.understood == sess.understood
    again.close()
    # Without material hints the words are not read onto the volume: nothing to say.
    off = RunSettings(population=4, generations=1, image_size=32, seed=0, material_hints=False)
    assert Session.create(vol, intent=intent, settings=off).understood == []


def test_new_words_in_the_middle_of_a_run_are_read_again(tmp_path):
    from intuitf.session.store import RunStore

    vol = phantom(32)
    settings = RunSettings(population=4, generations=3, image_size=32, output_size=32, seed=0)
    sess = Session.create(
        vol,
        intent=Intent(kind="text", text="red bone"),
        settings=settings,
        run_dir=tmp_path / "run",
    )
    sess.step()
    sess.query(Intent(kind="text", text="blue skin and a widget"), generations=1)
    # The lines describe the words now asked, not the first ones.
    assert sess.understood[0].startswith('"skin": blue')
    assert sess.understood[-1] == "not understood: widget"
    assert not any(line.startswith('"bone"') for line in sess.understood)
    # The Explorer's hints are the new words' too.
    assert [h.name for h in sess.explorer.hints] == ["skin"]
    sess.step()
    sess.close()
    journal = [json.loads(x) for x in (tmp_path / "run" / "journal.jsonl").read_text().splitlines()]
    asked = next(e for e in journal if e["type"] == "query")
    assert asked["understood"] == sess.understood
    # What the web app and the MCP tools list, and a resumed run, say the same.
    assert RunStore(tmp_path).run("run").understood == sess.understood
    again = Session.resume(tmp_path / "run", vol)
    assert again.understood == sess.understood
    again.close()
