"""A model names the structures from the atlas; the fake server answers from label volumes."""

from __future__ import annotations

import numpy as np

from helpers.shapes import potted_tree
from intuitf.evaluator.types import Intent
from intuitf.intent.atlas import atlas_messages, name_structures, parse_names
from intuitf.intent.hints import intent_hints, structure_map_of
from intuitf.testing.fake_labels import LabelNamer, atlas_descriptors, is_atlas_request
from intuitf.testing.fake_mllm import FakeMLLMServer
from intuitf.volume import Volume


def tree_and_labels():
    data = potted_tree()
    labels = np.zeros(data.shape, np.int16)
    labels[data >= 0.7] = 1
    labels[(data >= 0.4) & (data < 0.7)] = 2
    labels[(data >= 0.15) & (data < 0.3)] = 3
    vol = Volume.from_array(data, value_range=(0.0, 1.0))
    return vol, labels


def test_the_atlas_request_carries_every_structure_and_reads_back():
    vol, _ = tree_and_labels()
    smap = structure_map_of(vol)
    msgs = atlas_messages(smap, {s.id: np.zeros((8, 8, 3), np.uint8) for s in smap.foreground()})
    body = {"messages": msgs}
    assert is_atlas_request(body)
    assert [d["id"] for d in atlas_descriptors(body)] == [f"S{s.id}" for s in smap.foreground()]
    images = [p for p in msgs[0]["content"] if p["type"] == "image_url"]
    assert len(images) == len(smap.foreground())
    assert parse_names('Sure: ```{"names": {"S1": " Leaves ", "S9": "x", "T": "y"}}```', smap) == {
        1: "leaves"
    }


def test_names_from_the_labels_and_words_follow_them():
    vol, labels = tree_and_labels()
    names = {1: "pot", 2: "trunk", 3: "leaves"}
    with FakeMLLMServer(target=np.zeros((8, 8, 3), np.uint8),
                        labeller=LabelNamer(vol.data, labels, names, error_rate=0.0)) as srv:  # fmt: skip
        named = name_structures(vol, srv.base_url, size=48)
    got = {s.name for s in named.foreground()}
    assert {"pot", "trunk", "leaves"} <= got
    pot = next(s for s in named.foreground() if s.name == "pot")
    assert pot.value_range[0] > 0.7


def test_a_name_beats_the_descriptors():
    # The labeller calls the bowl "leaves" and the scattered specks "pot": words follow names.
    vol, labels = tree_and_labels()
    swapped = {1: "leaves", 2: "trunk", 3: "pot"}
    with FakeMLLMServer(target=np.zeros((8, 8, 3), np.uint8),
                        labeller=LabelNamer(vol.data, labels, swapped, error_rate=0.0)) as srv:  # fmt: skip
        name_structures(vol, srv.base_url, size=48)
    th = intent_hints(Intent(kind="text", text="brown pot and golden leaves"), vol)
    by = {h.material: h for h in th.hints}
    assert by["pot"].center < 0.3 and by["leaves"].center > 0.7


def test_the_labeller_errs_at_its_rate():
    vol, labels = tree_and_labels()
    namer = LabelNamer(vol.data, labels, {1: "pot", 2: "trunk", 3: "leaves"}, error_rate=1.0)
    desc = {"bbox": [0, 0, 0, 1, 1, 0.3], "values": [0.8, 0.9]}
    assert namer.name_of(desc) != "pot"
    assert LabelNamer(vol.data, labels, {1: "pot"}, error_rate=0.0).name_of(desc) == "pot"
