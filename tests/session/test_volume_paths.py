"""A run records its volume's absolute path (and, inside the run's parent tree, the path from
the run folder): it continues from any working directory, and from a moved tree."""

from __future__ import annotations

import json
import shutil

import numpy as np

from intuitf.session import Session
from intuitf.session.spec import parse_spec
from intuitf.volume.phantom import phantom_array

SETTINGS = {"population": 4, "generations": 2, "image_size": 32, "output_size": 32, "top_k": 1}


def _spec(source: str) -> dict:
    return {"volume": source, "settings": dict(SETTINGS)}


def test_a_relative_path_is_stored_absolute_and_resumes_from_another_cwd(tmp_path, monkeypatch):
    work = tmp_path / "project"
    work.mkdir()
    np.save(work / "head.npy", phantom_array(24, 1))
    monkeypatch.chdir(work)
    with Session.open(_spec("head.npy"), work / "runs" / "r1") as s:
        s.step()
    spec = json.loads((work / "runs" / "r1" / "run.json").read_text())["spec"]
    assert spec["volume"]["source"] == str(work / "head.npy")
    assert spec["volume"]["relative"] == "../../head.npy"

    monkeypatch.chdir(tmp_path)  # elsewhere: the recorded absolute path is used
    with Session.resume(work / "runs" / "r1") as s:
        out = s.run(write_outputs=False)
    assert out.completed and out.generations_done == 2


def test_a_moved_tree_finds_its_volume_by_the_relative_path_and_says_so(tmp_path, monkeypatch):
    tree = tmp_path / "a"
    tree.mkdir()
    np.save(tree / "head.npy", phantom_array(24, 1))
    with Session.open(_spec(str(tree / "head.npy")), tree / "r1") as s:
        s.step()
    moved = tmp_path / "b"
    shutil.move(tree, moved)
    monkeypatch.chdir(tmp_path)
    with Session.resume(moved / "r1") as s:
        assert any("relative to the run folder" in n for n in s.volume.notes)
        out = s.run(write_outputs=False)
    assert out.completed


def test_builtin_sources_stay_as_given_and_outside_trees_have_no_relative(tmp_path):
    assert parse_spec({"volume": "phantom"}).volume.source == "phantom"
    far = parse_spec({"volume": "/data/scans/head.nii.gz"}).volume
    assert far.anchored("/home/u/a/b/c/runs/r1").relative is None  # far away: none
