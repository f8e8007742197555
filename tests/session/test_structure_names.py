"""A run with a model judge has its volume's structures named once, at the opening, paid from
its budget and recorded; the map is cached per volume on disk."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers.shapes import potted_tree
from intuitf.intent.hints import structure_map_of
from intuitf.session import Session
from intuitf.session.rundir import RunDirectory
from intuitf.session.structure_cache import cache_dir, cached_structure_map
from intuitf.testing.fake_labels import LabelNamer
from intuitf.testing.fake_mllm import FakeMLLMServer
from intuitf.volume import Volume

SETTINGS = {"population": 4, "generations": 1, "seed": 3, "image_size": 32, "output_size": 32,
            "top_k": 1, "name_structures": True}  # fmt: skip


@pytest.fixture(autouse=True)
def own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("INTUITF_CACHE_DIR", str(tmp_path / "cache"))


def tree():
    data = potted_tree()
    labels = np.zeros(data.shape, np.int16)
    labels[data >= 0.7] = 1
    labels[(data >= 0.4) & (data < 0.7)] = 2
    labels[(data >= 0.15) & (data < 0.3)] = 3
    return Volume.from_array(data, value_range=(0.0, 1.0)), labels


def spec(url, budget_calls=None):
    judge = {"spec": url, "options": {"max_retries": 0}}
    if budget_calls is not None:
        judge["budget_calls"] = budget_calls
    return {"volume": "phantom", "intent": "brown pot and golden leaves", "settings": SETTINGS,
            "judge": judge}  # fmt: skip


def atlas_requests(srv):
    return [r for r in srv.requests_log if "STRUCTURE ATLAS" in json.dumps(r)]


def test_a_model_judge_names_the_structures_once_and_the_run_records_them(tmp_path):
    vol, labels = tree()
    namer = LabelNamer(vol.data, labels, {1: "pot", 2: "trunk", 3: "leaves"}, error_rate=0.0)
    with FakeMLLMServer(target=np.zeros((32, 32, 3), np.uint8), labeller=namer) as srv:
        s = Session.open(spec(srv.base_url), tmp_path / "r", volume=vol)
        asked = srv.stats.requests
        assert len(atlas_requests(srv)) == 1 and asked == 1  # before the first generation
        names = {x.name for x in structure_map_of(vol).foreground()}
        assert {"pot", "trunk", "leaves"} <= names
        assert s.cost.calls == 1  # the atlas call is the run's spend
        out = s.run(write_outputs=False)
        s.close()
        sent = srv.stats.requests
        # A second run on the same volume (another object, read again) asks nothing.
        again = Volume.from_array(vol.data.copy(), value_range=(0.0, 1.0))
        s2 = Session.open(spec(srv.base_url), tmp_path / "r2", volume=again)
        s2.close()
        assert len(atlas_requests(srv)) == 1
    record = RunDirectory(tmp_path / "r").read_run()["structures"]
    assert {"pot", "trunk", "leaves"} <= set(record["names"].values())
    assert record["calls"] == 1 and not record["cached"] and record["warning"] is None
    assert out.cost.calls == sent  # the atlas call counted in the run cost
    gens = RunDirectory(tmp_path / "r").generations()
    assert sum(int(g["calls"]) for g in gens) == out.cost.calls
    second = RunDirectory(tmp_path / "r2").read_run()["structures"]
    assert second["cached"] and second["calls"] == 0


def test_the_atlas_call_counts_against_the_budget(tmp_path):
    vol, labels = tree()
    namer = LabelNamer(vol.data, labels, {1: "pot", 2: "trunk", 3: "leaves"}, error_rate=0.0)
    with FakeMLLMServer(target=np.zeros((32, 32, 3), np.uint8), labeller=namer) as srv:
        s = Session.open(spec(srv.base_url, budget_calls=50), tmp_path / "r", volume=vol)
        assert s.judge.budget.calls == 1
        s.close()


class BrokenNamer:
    """A labeller that fails (the server answers 500) or answers what is not names."""

    def __init__(self, fail: bool) -> None:
        self.fail = fail

    def answer(self, body: dict) -> str:
        if self.fail:
            raise RuntimeError("the labeller is down")
        return "I cannot tell."


@pytest.mark.parametrize("fail", [True, False])
def test_a_failed_naming_is_a_warning_and_the_run_goes_on(tmp_path, caplog, fail):
    vol, _ = tree()
    with FakeMLLMServer(target=np.zeros((32, 32, 3), np.uint8), labeller=BrokenNamer(fail)) as srv:
        s = Session.open(spec(srv.base_url), tmp_path / "r", volume=vol)
        out = s.run(write_outputs=False)
        s.close()
        assert len(atlas_requests(srv)) == 1
    assert out.completed
    record = RunDirectory(tmp_path / "r").read_run()["structures"]
    assert record["names"] == {} and "descriptors" in record["warning"]
    assert "could not name" in caplog.text or "named none" in caplog.text
    assert not any(x.name for x in structure_map_of(vol).structures)


def test_a_metric_judge_asks_nothing(tmp_path):
    vol, _ = tree()
    s = Session.open({**spec("metric"), "judge": {"spec": "metric"}}, tmp_path / "r", volume=vol)
    s.close()
    assert "structures" not in RunDirectory(tmp_path / "r").read_run()


def test_the_map_is_cached_on_disk_by_content_and_version(monkeypatch):
    import intuitf.intent.structures as structures

    vol, _ = tree()
    first = cached_structure_map(vol)
    files = sorted(p.name for p in cache_dir().iterdir())
    assert len(files) == 2 and files[0].endswith(f"-v{structures.STRUCTURE_MAP_VERSION}.json")
    # Another object with the same content reads it back instead of building it.
    calls = []
    real = structures.build_structure_map
    monkeypatch.setattr(structures, "build_structure_map",
                        lambda *a, **k: calls.append(1) or real(*a, **k))  # fmt: skip
    again = cached_structure_map(Volume.from_array(vol.data.copy(), value_range=(0.0, 1.0)))
    assert calls == []
    assert again.to_dict() == first.to_dict()
    assert again.labels is not None and np.array_equal(again.labels, first.labels)
    # A new map version misses and builds.
    monkeypatch.setattr(structures, "STRUCTURE_MAP_VERSION", structures.STRUCTURE_MAP_VERSION + 1)
    import intuitf.session.structure_cache as sc

    monkeypatch.setattr(sc, "STRUCTURE_MAP_VERSION", structures.STRUCTURE_MAP_VERSION)
    cached_structure_map(Volume.from_array(vol.data.copy(), value_range=(0.0, 1.0)))
    assert calls == [1]
    # Different content: another entry.
    other = Volume.from_array(np.flip(vol.data, 0).copy(), value_range=(0.0, 1.0))
    cached_structure_map(other)
    assert len(list(cache_dir().glob("*.json"))) == 3


def test_a_damaged_cache_entry_is_rebuilt():
    vol, _ = tree()
    cached_structure_map(vol)
    for p in cache_dir().glob("*.json"):
        p.write_text("{not json")
    again = cached_structure_map(Volume.from_array(vol.data.copy(), value_range=(0.0, 1.0)))
    assert again.foreground()


def test_a_resumed_run_finds_the_names_again(tmp_path):
    vol, labels = tree()
    namer = LabelNamer(vol.data, labels, {1: "pot", 2: "trunk", 3: "leaves"}, error_rate=0.0)
    with FakeMLLMServer(target=np.zeros((32, 32, 3), np.uint8), labeller=namer) as srv:
        Session.open(spec(srv.base_url), tmp_path / "r", volume=vol).close()
        again = Volume.from_array(vol.data.copy(), value_range=(0.0, 1.0))  # a new process
        with Session.resume(tmp_path / "r", volume=again):
            names = {x.name for x in structure_map_of(again).foreground()}
        assert {"pot", "trunk", "leaves"} <= names
        assert len(atlas_requests(srv)) == 1
