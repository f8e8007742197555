"""The Session as a service: specs, async stepping, events, control, branches, people, views."""

from __future__ import annotations

import asyncio
import json
import threading
import time

import numpy as np
import pytest

from intuitf.errors import SessionError
from intuitf.evaluator.types import Intent
from intuitf.session import RunSpec, RunStore, Session
from intuitf.session.events import read_events
from intuitf.session.scheduler import BATCH, INTERACTIVE, RenderScheduler
from intuitf.session.spec import parse_spec
from intuitf.session.views import pick_bar, pick_smallest, pick_whole
from intuitf.volume import phantom

SETTINGS = {"population": 6, "generations": 3, "image_size": 48, "output_size": 48, "top_k": 2}


@pytest.fixture(scope="module")
def vol():
    return phantom(size=40)


def _spec(**changes) -> RunSpec:
    base = dict(
        volume="phantom",
        intent={"kind": "text", "text": "opaque ivory bone, faint red skin"},
        judge="metric",
        settings=dict(SETTINGS),
    )
    base.update(changes)
    return RunSpec(**base)


def _generation_entries(run_dir):
    lines = (run_dir / "journal.jsonl").read_text().splitlines()
    by_gen = {}
    for e in map(json.loads, lines):
        if e["type"] == "generation":
            by_gen[e["generation"]] = e
    return [by_gen[g] for g in sorted(by_gen)]


# -- the spec ------------------------------------------------------------------------------
def test_plain_data_makes_a_valid_spec_and_bad_data_says_what_is_wrong():
    spec = RunSpec(
        volume="phantom",
        intent={"kind": "text", "text": "opaque ivory bone"},
        judge="metric",
        settings={"population": 6, "generations": 2, "image_size": 48},
    )
    assert spec.volume.source == "phantom" and spec.judge.spec == "metric"
    assert parse_spec(spec.to_dict()) == spec  # round trip through JSON-ready data
    with pytest.raises(SessionError) as err:
        parse_spec({"volume": "phantom", "intent": {"kind": "image"}, "settings": {"popul": 3}})
    assert "reference" in err.value.message and "popul" in err.value.message
    with pytest.raises(SessionError, match="population"):
        parse_spec({"volume": "phantom", "settings": {"population": 2}})


def test_a_run_folder_alone_resumes_it(vol, tmp_path):
    run = tmp_path / "r"
    with Session.open(_spec(), run, volume=vol) as s:
        s.step()
    record = json.loads((run / "run.json").read_text())
    assert record["spec"]["intent"]["text"].startswith("opaque")
    # The folder is enough: the volume and the judge come from the spec written there.
    with Session.resume(run) as resumed:
        assert resumed.generation == 1 and resumed.volume.name.startswith("phantom")
        out = resumed.run(write_outputs=False)
    assert out.completed and out.generations_done == 3


# -- async, events, control ----------------------------------------------------------------
def test_events_come_in_order_and_a_late_subscriber_misses_nothing(vol, tmp_path):
    run = tmp_path / "r"
    live = []
    with Session.open(_spec(), run, volume=vol) as s:
        s.events.subscribe(live.append)
        s.run(write_outputs=False)
        types = [e.type for e in live]
        # The session's own first event (stage_started, emitted by open) is replayed to a
        # subscriber that came after open; then the run's.
        assert types[:2] == ["stage_started", "run_started"] and types[-1] == "run_ended"
        assert [e.seq for e in live] == list(range(live[0].seq, live[-1].seq + 1))
        gens = [e.data["generation"] for e in live if e.type == "generation_ended"]
        assert gens == [0, 1, 2]
        m = next(e for e in live if e.type == "match_judged")
        assert {"first", "second", "per_aspect", "reasons", "cost", "winner"} <= set(m.data)
        # Every generation's matches come between its start and its end.
        for g in range(3):
            start = next(i for i, e in enumerate(live) if e.type == "generation_started"
                         and e.data["generation"] == g)  # fmt: skip
            end = next(i for i, e in enumerate(live) if e.type == "generation_ended"
                       and e.data["generation"] == g)  # fmt: skip
            inside = [e for e in live[start:end] if e.type == "match_judged"]
            assert inside and all(e.data["generation"] == g for e in inside)
        late = []
        s.events.subscribe(late.append, since=live[10].seq)
        assert [e.seq for e in late] == [e.seq for e in live[11:]]
    # Journaled: a process that starts later replays the same events from the file.
    on_disk = read_events(run / "events.jsonl")
    assert [e.seq for e in on_disk][-len(live) :] == [e.seq for e in live]


def test_two_sessions_run_at_once_in_one_event_loop(vol):
    async def main():
        a = Session.open(_spec(), None, volume=vol)
        b = Session.open(_spec(settings={**SETTINGS, "seed": 7}), None, volume=vol)
        seen = {"a": 0, "b": 0}

        def count(name):
            return lambda e: seen.__setitem__(name, seen[name] + (e.type == "match_judged"))

        a.events.subscribe(count("a"))
        b.events.subscribe(count("b"))
        with pytest.raises(SessionError, match="astep"):
            a.step()  # inside a running loop the synchronous wrapper refuses clearly
        oa, ob = await asyncio.gather(a.arun(write_outputs=False), b.arun(write_outputs=False))
        return oa, ob, seen, a.snapshot()

    oa, ob, seen, snap = asyncio.run(main())
    assert oa.completed and ob.completed and seen["a"] > 0 and seen["b"] > 0
    assert snap.status == "ended" and snap.generation == 3 and snap.ranking


def test_snapshot_is_safe_to_read_from_another_thread_while_running(vol):
    s = Session.open(_spec(), None, volume=vol)
    seen, stop = [], threading.Event()

    def reader():
        while not stop.is_set():
            snap = s.snapshot()
            assert len(snap.ranking) in (0, SETTINGS["population"])
            seen.append(snap.generation)
            time.sleep(0.001)

    t = threading.Thread(target=reader)
    t.start()
    try:
        s.run(write_outputs=False)
    finally:
        stop.set()
        t.join()
    assert seen and max(seen) <= 3


def test_pause_holds_between_matches_and_cancel_replays_with_nothing_repaid(vol, tmp_path):
    from intuitf.evaluator.cache import VerdictCache
    from intuitf.evaluator.mllm import MLLMJudge
    from intuitf.testing.fake_mllm import FakeMLLMServer

    ref_img = phantom(size=40).data[20] * 255
    target = np.repeat(ref_img[:48, :48, None], 3, axis=2).astype(np.uint8)
    with FakeMLLMServer(target=target, latency=0.01) as srv:

        def judge(path):
            return MLLMJudge("default", base_url=srv.base_url, swap="never",
                             cache=VerdictCache(path), max_retries=0)  # fmt: skip

        # An uninterrupted run, for reference.
        with Session.open(_spec(), tmp_path / "ref", volume=vol,
                          judge=judge(tmp_path / "ref.sqlite")) as ref:  # fmt: skip
            ref.run(write_outputs=False)
        straight = srv.stats.requests

        run = tmp_path / "r"
        s = Session.open(_spec(), run, volume=vol, judge=judge(run.parent / "r.sqlite"))
        matches = []

        def control(e):
            if e.type == "match_judged" and e.data["generation"] == 1:
                matches.append(e)
                if len(matches) == 1:
                    s.pause()
                    threading.Timer(0.3, s.proceed).start()
                elif len(matches) == 4:
                    s.cancel()

        s.events.subscribe(control)
        out = s.run(write_outputs=False)
        assert out.reason == "cancelled" and s.generation == 1
        statuses = [e.data["status"] for e in s.events.since(0) if e.type == "status"]
        assert statuses[:3] == ["paused", "running", "cancelling"]
        # Matches already asked finish; none is asked while paused: the next round's came
        # after proceed().
        later = next(m for m in matches if m.data["round"] > matches[0].data["round"])
        assert later.time - matches[0].time >= 0.25
        s.close()
        with Session.resume(run, vol, judge(run.parent / "r.sqlite")) as resumed:
            out = resumed.run(write_outputs=False)
        assert out.completed
        # The cancelled generation was replayed from the verdict store: no request twice.
        assert srv.stats.requests - straight == straight
        assert resumed.last_ranking == ref.last_ranking


# -- branches ------------------------------------------------------------------------------
def test_a_branch_from_generation_k_reproduces_the_parent(vol, tmp_path):
    parent = tmp_path / "parent"
    settings = {**SETTINGS, "generations": 4}
    with Session.open(_spec(settings=settings), parent, volume=vol) as p:
        p.run(write_outputs=False)
    assert (parent / "checkpoints" / "gen002.json").exists()
    with Session.branch(parent, tmp_path / "child", generation=2, volume=vol) as c:
        assert c.generation == 2 and c.spec.parent.generation == 2
        c.run(write_outputs=False)
    want = _generation_entries(parent)[2:]
    got = _generation_entries(tmp_path / "child")
    assert [e["generation"] for e in got] == [2, 3]
    for a, b in zip(want, got, strict=True):
        assert [c["tf"] for c in a["candidates"]] == [c["tf"] for c in b["candidates"]]
        assert a["best_id"] == b["best_id"]
    # The store draws the branch under its parent.
    tree = RunStore(tmp_path).tree()
    assert [n["run"]["name"] for n in tree] == ["parent"]
    assert tree[0]["children"][0]["run"]["name"] == "child"


def test_a_branch_from_a_candidate_starts_with_it(vol, tmp_path):
    with Session.open(_spec(), tmp_path / "p", volume=vol) as p:
        p.run(write_outputs=False)
        best = p.last_ranking[0]
        tf = p.tfs[best]
    with Session.branch(tmp_path / "p", tmp_path / "b", candidate=best, volume=vol,
                        changes={"intent": {"kind": "text", "text": "gold bone"}}) as b:  # fmt: skip
        first = b.explorer.ask()
        assert tf.gaussians in [c.tf.gaussians for c in first]
        assert b.intent.text == "gold bone" and b.spec.parent.candidate == best


# -- a person in the loop ------------------------------------------------------------------
def test_a_persons_verdict_changes_what_the_explorer_is_told_and_undo_restores_it(vol):
    s = Session.open(_spec(), None, volume=vol)
    s.step()
    s.step()
    model_ranking = list(s.last_ranking)
    next_pop = [c.tf for c in s.explorer.ask()]
    loser, winner = model_ranking[0], model_ranking[-1]
    v = s.prefer(winner, loser)
    assert v.source == "human" and s.last_ranking.index(winner) < s.last_ranking.index(loser)
    changed_pop = [c.tf for c in s.explorer.ask()]
    assert changed_pop != next_pop  # the Explorer was told another ranking
    s.undo_verdict(v.id)
    assert s.last_ranking == model_ranking
    assert [c.tf for c in s.explorer.ask()] == next_pop
    # Best-of: the chosen one ends on top of those it was chosen among.
    among = model_ranking[2:5]
    s.choose_best(among[-1], among)
    assert s.last_ranking.index(among[-1]) < min(s.last_ranking.index(c) for c in among[:-1])
    kinds = [e.data["action"] for e in s.events.since(0) if e.type == "human_verdict"]
    assert kinds == ["added", "undone", "added"]
    with pytest.raises(SessionError):
        s.prefer("g999-000", loser)


def test_a_new_query_starts_a_customize_stage_and_keeps_the_history(vol, tmp_path):
    with Session.open(_spec(), tmp_path / "q", volume=vol) as s:
        s.run(write_outputs=False)
        before = list(s.explorer.hints)
        s.query(Intent(kind="text", text="blue translucent skin"), generations=2)
        assert list(s.explorer.hints) != before  # the new words name their own materials
        assert s.plan[-1] == ("customize", 2) and not s.done and s.stage == "customize"
        out = s.run(write_outputs=False)
    assert out.completed and out.generations_done == 5
    gens = _generation_entries(tmp_path / "q")
    assert [e["generation"] for e in gens] == [0, 1, 2, 3, 4]
    with Session.resume(tmp_path / "q", vol) as again:  # the query's intent survives a resume
        assert again.intent.text == "blue translucent skin" and again.done


# -- views ---------------------------------------------------------------------------------
def test_pick_chooses_the_visible_feature_of_smallest_area():
    attr = np.zeros((3, 8, 8), dtype=np.float32)
    attr[0] = 0.5  # everywhere
    attr[1, 2:6, 2:6] = 0.3  # a 4x4 block
    attr[2, 3:5, 3:5] = 0.01  # too faint to count as visible
    picked = pick_smallest(attr, x=3, y=3)
    assert picked.index == 1 and [v[0] for v in picked.visible] == [1, 0]
    assert picked.mask.sum() == 16
    assert pick_smallest(attr, x=0, y=0).index == 0
    assert pick_smallest(np.zeros((2, 4, 4), np.float32), 1, 1).index is None


def test_a_speck_tinting_the_pixel_does_not_take_the_click():
    # A pot (large) under the cursor, with a few pixels of bright noise in front of it that
    # give the pixel 6 % of its opacity: the click selects the pot, not the speck.
    attr = np.zeros((3, 8, 8), dtype=np.float32)
    attr[0] = 0.2  # soil and trunk, everywhere
    attr[1, 2:6, 2:6] = 0.7  # the pot
    attr[2, 3, 3] = 0.06  # the speck: visible, but a small part of the pixel
    picked = pick_smallest(attr, x=3, y=3)
    assert picked.index == 1
    assert [v[0] for v in picked.visible] == [2, 1, 0]  # still listed as visible there
    # Where the speck is most of what the pixel shows, it is what the click means.
    attr[2, 3, 3] = 0.5
    assert pick_smallest(attr, x=3, y=3).index == 2
    # Where eight features each make an eighth of the pixel, none reaches the bar: the
    # largest share still competes, so the smallest of those is picked.
    many = np.zeros((8, 8, 8), dtype=np.float32)
    for i in range(8):
        many[i, : i + 1] = 0.1  # feature i covers i + 1 rows: feature 0 is the smallest
    many[3, 0, 0] = 0.12
    assert pick_smallest(many, x=0, y=0).index == 3


def test_a_whole_pick_selects_every_feature_that_makes_the_pixel():
    # A pot drawn by two Gaussians (a dense core over most of it, a rim where it is seen
    # edge-on), soil everywhere behind, and a speck that only tints the pixel.
    attr = np.zeros((4, 8, 8), dtype=np.float32)
    attr[0] = 0.05  # soil: visible, under the bar at the pot
    attr[1, 2:7, 2:7] = 0.25  # the pot's core
    attr[2, 3:5, 3:5] = 0.65  # the pot's rim, the smaller
    attr[3, 3, 3] = 0.03  # the speck
    one = pick_smallest(attr, x=3, y=3)
    assert one.index == 2 and one.selected == (2,) and one.mask.sum() == 4
    whole = pick_whole(attr, x=3, y=3)
    assert whole.index == 2  # the paper's choice is still named
    assert whole.selected == (1, 2)  # the soil and the speck make too little of the pixel
    assert whole.mask.sum() == 25 and not whole.mask[0, 0]
    assert [v[0] for v in whole.visible] == [3, 2, 1, 0]
    assert pick_whole(np.zeros((2, 4, 4), np.float32), 1, 1).selected == ()


def test_views_leave_the_judging_camera_and_images_alone(vol):
    from intuitf.render import Camera

    s = Session.open(_spec(), None, volume=vol)
    s.step()
    cid = s.last_ranking[0]
    judged = s.image(cid, s.tfs[cid]).copy()
    camera = s.camera
    side = s.view(cid, Camera(azimuth=90, elevation=10), size=48)
    assert side.shape == (48, 48, 3) and not np.array_equal(side, judged)
    p = s.pick(cid, Camera(azimuth=90, elevation=10), x=24, y=24, size=48)
    feats = s.features(cid, Camera(azimuth=90, elevation=10), size=48)
    assert len(feats) == len(s.tfs[cid])
    if p.index is not None:  # the smallest of the features that make the pixel
        bar = pick_bar(p.visible)
        areas = {i: a for i, share, a in p.visible if share >= bar}
        assert areas[p.index] == min(areas.values())
        assert p.selected == (p.index,)
        whole = s.pick(cid, Camera(azimuth=90, elevation=10), x=24, y=24, size=48, whole=True)
        assert whole.selected == tuple(sorted(areas)) and whole.index == p.index
    assert s.camera == camera and np.array_equal(s.image(cid, s.tfs[cid]), judged)


def test_interactive_renders_go_ahead_of_waiting_batch_renders():
    sched = RenderScheduler()
    order, gate = [], threading.Event()
    first = sched.submit(lambda: gate.wait(5), BATCH)  # occupies the worker
    batch = [sched.submit(lambda i=i: order.append(f"batch{i}"), BATCH) for i in range(3)]
    inter = sched.submit(lambda: order.append("interactive"), INTERACTIVE)
    gate.set()
    for f in [first, *batch, inter]:
        f.result(5)
    assert order[0] == "interactive"


# -- the store -----------------------------------------------------------------------------
def test_store_lists_runs_and_finds_any_candidate(vol, tmp_path):
    with Session.open(_spec(), tmp_path / "foot", volume=vol) as s:
        s.run(write_outputs=False)
        first_gen_best = s.records[0].best_id
    store = RunStore(tmp_path)
    (info,) = store.runs()
    assert info.name == "foot" and info.status == "completed" and info.generations_done == 3
    c = store.candidate(f"foot/{first_gen_best}")
    assert c.generation == 0 and c.rank == 1
    img = store.render(f"foot/{first_gen_best}", volume=vol)
    assert img.shape == (48, 48, 3)
    assert [h["generation"] for h in store.history("foot")] == [0, 1, 2]
    assert store.new_name("foot") == "foot-2"
    with pytest.raises(SessionError):
        store.path_of("../etc")
    with pytest.raises(SessionError):
        store.candidate("foot/g009-000")
