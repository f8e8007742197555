"""A volume's voxel size set in the web app: every view after it uses it, even one whose
load began before."""

from __future__ import annotations

import threading

import numpy as np

from intuitf.web.volumes import VolumeCatalog


def test_a_load_begun_before_a_new_spacing_is_not_served_after_it(tmp_path, monkeypatch):
    raw = tmp_path / "ct_8x6x4_uint8.raw"
    np.arange(8 * 6 * 4, dtype=np.uint8).tofile(raw)
    cat = VolumeCatalog([str(raw)])
    vid = next(e.id for e in cat.entries() if e.kind == "arg")
    assert tuple(cat.load(vid).spacing) == (1.0, 1.0, 1.0)
    cat.set_spacing(vid, [1, 1, 1.5])  # forget the first load

    # A load that is still reading when the user sets another voxel size.
    from intuitf.session.spec import VolumeSpec

    real_load, started, release = VolumeSpec.load, threading.Event(), threading.Event()

    def slow_load(self, *a, **k):
        started.set()
        release.wait(10)
        return real_load(self, *a, **k)

    monkeypatch.setattr(VolumeSpec, "load", slow_load)
    old = []
    t = threading.Thread(target=lambda: old.append(cat.load(vid)))
    t.start()
    assert started.wait(10)
    cat.set_spacing(vid, [1, 1, 2])
    release.set()
    t.join(10)
    assert tuple(old[0].spacing) == (1.0, 1.0, 1.5)  # it finishes with what it was asked
    monkeypatch.setattr(VolumeSpec, "load", real_load)
    assert tuple(cat.load(vid).spacing) == (1.0, 1.0, 2.0)  # the next view gets the new one


def test_what_is_built_from_a_volume_follows_a_new_spacing(tmp_path, monkeypatch):
    import intuitf.session.building as building

    raw = tmp_path / "ct_8x6x4_uint8.raw"
    np.arange(8 * 6 * 4, dtype=np.uint8).tofile(raw)
    cat = VolumeCatalog([str(raw)])
    vid = next(e.id for e in cat.entries() if e.kind == "arg")
    built = []

    def camera_for(vol):  # stands for the view chosen from the volume's structures
        built.append(tuple(vol.spacing))
        return {"spacing": list(vol.spacing)}

    monkeypatch.setattr(building, "default_camera", camera_for)
    assert cat.camera(vid) == cat.camera(vid) == {"spacing": [1.0, 1.0, 1.0]}
    assert len(built) == 1  # kept
    cat.set_spacing(vid, [1, 1, 3])
    assert cat.camera(vid) == {"spacing": [1.0, 1.0, 3.0]}
