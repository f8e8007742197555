"""One default judging camera for every front end, decided by the session's building code.

A run opened from the CLI, from the web and from the Python API with no camera given is judged
from the same camera (:func:`intuitf.session.building.default_camera`), and the camera chosen is
recorded with the run. A sketch drawn on a picture intuitf rendered is judged from that
picture's camera, whichever front end opened it.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
from fastapi.testclient import TestClient

from helpers.web_backend import AUTH, make_app, wait_run
from intuitf.imageio import render_record, save_png
from intuitf.render import Camera
from intuitf.session import RunDirectory, RunSpec, Session
from intuitf.session.building import default_camera

SMALL = {"population": 4, "generations": 1, "image_size": 32, "output_size": 32, "top_k": 1}


def _recorded_camera(run_dir) -> dict:
    return RunDirectory(run_dir).read_run()["settings"]["camera"]


def test_cli_web_and_python_api_judge_from_the_same_default_camera(tmp_path):
    spec = RunSpec.model_validate({"volume": {"source": "phantom"}, "settings": SMALL})
    # The session's choice for this volume (the same volume every front end opens).
    expected = default_camera(spec.volume.load(), spec)
    assert expected != Camera().to_dict()  # a chosen view, not straight on

    # Python API: a spec with no camera.
    with Session.open(spec, tmp_path / "api") as s:
        assert s.camera.to_dict() == expected
    assert _recorded_camera(tmp_path / "api") == expected

    # In-memory objects (Session.create) take the default the same way.
    from intuitf.volume.phantom import phantom

    vol = phantom(32)
    with Session.create(vol) as s:
        assert s.camera.to_dict() == default_camera(vol)

    # CLI: optimize with no --azimuth/--elevation.
    cli = tmp_path / "cli"
    proc = subprocess.run(
        [sys.executable, "-m", "intuitf", "optimize", "phantom", "--population", "4",
         "--generations", "1", "--size", "32", "--output-size", "32", "--top", "1",
         "-o", str(cli)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert _recorded_camera(cli) == expected

    # Web: a run started from the page's API with no camera in its settings.
    runs = tmp_path / "web"
    with TestClient(make_app(runs, default_settings=SMALL)) as client:
        r = client.post("/api/runs", json={"volume": "phantom"}, headers=AUTH)
        assert r.status_code == 201, r.text
        name = r.json()["name"]
        wait_run(client, name)
    assert _recorded_camera(runs / name) == expected


def test_a_sketch_is_judged_from_its_base_pictures_camera(tmp_path):
    cam = Camera(azimuth=75.0, elevation=-10.0)
    base = save_png(np.zeros((32, 32, 3), np.uint8), tmp_path / "base.png",
                    metadata=render_record(cam, (32, 32), "phantom"))  # fmt: skip
    sketch = np.zeros((32, 32, 4), np.uint8)
    sketch[10:20, 10:20] = (255, 0, 0, 255)
    save_png(sketch, tmp_path / "sketch.png")
    spec = RunSpec.model_validate(
        {
            "volume": {"source": "phantom"},
            "intent": {"kind": "sketch", "sketch": str(tmp_path / "sketch.png"),
                       "base": str(base)},
            "settings": SMALL,
        }
    )  # fmt: skip
    with Session.open(spec, tmp_path / "run") as s:
        assert s.camera.to_dict() == cam.to_dict()
    assert _recorded_camera(tmp_path / "run") == cam.to_dict()
    # A camera the spec names wins.
    named = Camera(azimuth=10.0).to_dict()
    spec2 = spec.model_copy(update={"settings": {**SMALL, "camera": named}})
    with Session.open(spec2, None) as s:
        assert s.camera.to_dict() == named
