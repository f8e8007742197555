"""The Session loop end to end: runs, journals, checkpoints, resumes, and ends cleanly."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from intuitf.errors import BudgetExhausted
from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.ratings import HISTORY_FADE
from intuitf.evaluator.tournament import SwissTournament, default_rounds
from intuitf.evaluator.types import Intent
from intuitf.session import RunDirectory, RunSettings, Session
from intuitf.volume import phantom

SETTINGS = dict(population=8, generations=4, seed=3, image_size=64, output_size=96, top_k=2)


@pytest.fixture(scope="module")
def vol():
    return phantom(size=48)


def _intent():
    return Intent(kind="text", text="opaque white bone, faint red skin", about="a phantom head")


def _best_tfs(outcome):
    return [tf.to_dict() for tf, _ in outcome.best]


def test_run_in_memory_improves_and_keeps_elites(vol):
    s = Session.create(vol, intent=_intent(), settings=RunSettings(**SETTINGS))
    out = s.run()
    assert out.completed and out.generations_done == 4
    assert s.plan == [("initialize", 1), ("customize", 3)]
    # The best of each generation survives into the next one unchanged (elitism).
    for prev, nxt in zip(s.records, s.records[1:], strict=False):
        assert prev.best_id in [c["id"] for c in nxt.candidates]


def test_run_folder_has_every_output(vol, tmp_path):
    run = tmp_path / "run"
    s = Session.create(vol, intent=_intent(), settings=RunSettings(**SETTINGS), run_dir=run)
    out = s.run()
    assert out.completed
    rd = RunDirectory(run)
    record = json.loads(rd.run_json.read_text())
    assert record["settings"]["seed"] == 3 and record["intent"]["text"].startswith("opaque")
    gens = [e for e in rd.read_journal() if e["type"] == "generation"]
    assert [e["generation"] for e in gens] == [0, 1, 2, 3]
    assert all(len(e["candidates"]) == 8 for e in gens)
    assert rd.read_journal()[-1]["type"] == "end"
    for name in (
        "rank01.png",
        "rank01.tf.json",
        "rank01.tf.png",
        "rank01.paraview.json",
        "rank01.vp",
        "rank01.vtk.py",
        "rank01.1dt",
        "rank02.png",
    ):
        assert (run / "best" / name).stat().st_size > 0, name
    assert (run / "generations" / "gen003.png").exists()
    assert (run / "evolution.png").exists()
    html = (run / "report.html").read_text()
    assert "data:image/png;base64," in html
    tf = json.loads((run / "best" / "rank01.tf.json").read_text())
    assert tf["value_range"] == list(vol.value_range)


def test_interrupted_run_resumes_to_the_same_result(vol, tmp_path):
    with Session.create(
        vol, intent=_intent(), settings=RunSettings(**SETTINGS), run_dir=tmp_path / "a"
    ) as first:
        ref = first.run()

    def interrupt_in_generation_2(event):
        if event.type == "match_judged" and event.data["generation"] == 2:
            raise KeyboardInterrupt

    s = Session.create(
        vol, intent=_intent(), settings=RunSettings(**SETTINGS), run_dir=tmp_path / "b"
    )
    s.events.subscribe(interrupt_in_generation_2)
    out = s.run()
    assert out.reason == "interrupted" and out.generations_done == 2
    s.close()
    resumed = Session.resume(tmp_path / "b", vol, s.judge)
    assert resumed.generation == 2 and resumed.stage == "customize"
    out2 = resumed.run()
    assert out2.completed and out2.generations_done == 4
    assert _best_tfs(out2) == _best_tfs(ref)


def test_budget_stop_is_clean_and_saved(vol, tmp_path):
    class BrokeJudge:
        """Answers like the metric judge until its budget runs out."""

        name = "broke"

        def __init__(self, inner, calls):
            self.inner, self.left = inner, calls

        async def compare(self, a, b, aspects, intent):
            if self.left <= 0:
                raise BudgetExhausted("The call budget is spent.")
            self.left -= 1
            return await self.inner.compare(a, b, aspects, intent)

    from intuitf.evaluator.metric import MetricJudge

    judge = BrokeJudge(MetricJudge(), calls=40)
    s = Session.create(
        vol, intent=_intent(), judge=judge, settings=RunSettings(**SETTINGS), run_dir=tmp_path / "r"
    )
    out = s.run()
    s.close()
    assert out.reason == "budget"
    assert 1 <= out.generations_done < 4
    rd = RunDirectory(tmp_path / "r")
    assert rd.read_checkpoint()["generation"] == out.generations_done
    kinds = [e["type"] for e in rd.read_journal()]
    assert "partial" in kinds and kinds[-1] == "end"
    assert (tmp_path / "r" / "best" / "rank01.png").exists()


def test_branch_from_an_earlier_result_starts_with_it(vol):
    first = Session.create(vol, intent=_intent(), settings=RunSettings(**SETTINGS)).run()
    tf, _ = first.best[0]
    s = Session.create(vol, intent=_intent(), settings=RunSettings(**SETTINGS), initial=[tf])
    s.step()
    assert tf.to_dict()["gaussians"] in [r["tf"]["gaussians"] for r in s.records[0].candidates]


def test_refine_changes_only_the_selected_gaussians(vol):
    start = Session.create(vol, intent=_intent(), settings=RunSettings(**SETTINGS)).run()
    tf, _ = start.best[0]
    s = Session.refine(
        vol, tf, [1], "make this feature bright green", settings=RunSettings(**SETTINGS)
    )
    assert s.plan == [("refine", 4)] and s.intent.kind == "edit" and s.intent.base is not None
    out = s.run()
    assert out.completed
    others = [g for i, g in enumerate(tf.gaussians) if i != 1]
    for rec in s.records:
        for c in rec.candidates:
            gs = c["tf"]["gaussians"]
            kept = [g for i, g in enumerate(gs) if i != 1]
            assert [(g["mean"], g["width"], g["height"], g["color"]) for g in kept] == [
                (g.mean, g.width, g.height, list(g.color)) for g in others
            ]
    changed = {tuple(c["tf"]["gaussians"][1]["color"]) for rec in s.records for c in rec.candidates}
    assert len(changed) > 1


def test_full_disk_ends_cleanly_and_the_run_resumes(vol, tmp_path, monkeypatch):
    import errno
    import os

    ref = Session.create(vol, intent=_intent(), settings=RunSettings(**SETTINGS)).run()
    real_replace = os.replace
    checkpoints = []

    def replace_until_disk_fills(src, dst):
        if str(dst).endswith("checkpoint.json"):
            if len(checkpoints) >= 2:
                raise OSError(errno.ENOSPC, "No space left on device")
            checkpoints.append(dst)
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace_until_disk_fills)
    run = tmp_path / "run"
    with Session.create(
        vol, intent=_intent(), settings=RunSettings(**SETTINGS), run_dir=run
    ) as broken:
        out = broken.run()
    assert out.reason == "storage" and "disk is full" in out.message
    monkeypatch.setattr(os, "replace", real_replace)
    rd = RunDirectory(run)
    assert rd.read_checkpoint()["generation"] == 2  # the last checkpoint that fit is intact
    resumed = Session.resume(run, vol, Session.create(vol, settings=RunSettings(**SETTINGS)).judge)
    out2 = resumed.run()
    assert out2.completed
    assert _best_tfs(out2) == _best_tfs(ref)


def test_verdicts_of_the_stage_carry_over_and_reset_with_the_stage(vol, tmp_path):
    s = Session.create(
        vol, intent=_intent(), settings=RunSettings(**SETTINGS), run_dir=tmp_path / "r"
    )
    s.step()  # initialize's only generation: the stage changes after it
    assert s.stage == "customize" and s.stage_games == []
    rec = s.step()
    n = len(rec.candidates)
    assert len(s.stage_games) == default_rounds(n) * (n // 2)  # every verdict of the stage
    assert {g[0] for g in s.stage_games} <= {c["id"] for c in rec.candidates}
    assert {g[3] for g in s.stage_games} == {rec.generation}  # when each was played
    ckpt = json.loads((tmp_path / "r" / "checkpoint.json").read_text())
    assert [tuple(g) for g in ckpt["stage_games"]] == [tuple(g) for g in s.stage_games]
    s.step()  # the next tournament fits them with its own verdicts: the list grows
    assert len(s.stage_games) > len(ckpt["stage_games"])
    s.close()


class _ModelLike:
    """The metric's verdicts from a judge that does not say it is deterministic (a model)."""

    name = "model-like"

    def __init__(self) -> None:
        self._metric = MetricJudge()

    async def compare(self, first, second, aspects, intent):
        return await self._metric.compare(first, second, aspects, intent)


@pytest.mark.parametrize("judge", ["metric", "model"])
def test_earlier_generations_verdicts_fade_unless_the_judge_is_deterministic(
    vol, judge, monkeypatch
):
    histories = []
    play = SwissTournament.run

    async def spy(self, images, ids, prior=None, progress=None, history=(), on_match=None):
        histories.append(list(history))
        return await play(self, images, ids, prior, progress, history, on_match)

    monkeypatch.setattr(SwissTournament, "run", spy)
    j = MetricJudge() if judge == "metric" else _ModelLike()
    s = Session.create(vol, intent=_intent(), judge=j, settings=RunSettings(**SETTINGS))
    for _ in range(3):  # initialize, then two generations of customize
        s.step()
    s.close()
    assert histories[1] == []  # a new stage starts without history
    weights = {round(w, 9) for *_, w in histories[2]}
    assert weights == ({1.0} if judge == "metric" else {round(HISTORY_FADE, 9)})
    assert len(histories[2]) == len([g for g in s.stage_games if g[3] == 1])


def test_a_checkpoint_whose_verdicts_lack_their_generation_resumes(vol, tmp_path):
    # Checkpoints written before verdicts faded with age hold (first, second, score).
    s = Session.create(
        vol, intent=_intent(), settings=RunSettings(**SETTINGS), run_dir=tmp_path / "r"
    )
    s.step()
    s.step()
    s.close()
    path = tmp_path / "r" / "checkpoint.json"
    ckpt = json.loads(path.read_text())
    ckpt["stage_games"] = [g[:3] for g in ckpt["stage_games"]]
    path.write_text(json.dumps(ckpt))
    resumed = Session.resume(tmp_path / "r", vol, s.judge)
    # ... read as verdicts of the generation before the one to play
    assert {g[3] for g in resumed.stage_games} == {resumed.generation - 1}
    assert resumed.step().generation == 2
    resumed.close()


@pytest.mark.parametrize("method", ["ga", "paper-ga", "cmaes", "random"])
def test_every_explorer_method_runs_a_session_with_an_intent(vol, method):
    settings = RunSettings(**{**SETTINGS, "generations": 2, "explorer": method})
    s = Session.create(vol, intent=_intent(), settings=settings)
    out = s.run(write_outputs=False)
    assert out.completed and out.generations_done == 2
    # The colours named in the text reach every method as its palette.
    assert len(s.explorer.palette) == 2


def test_best_results_are_different_pictures(vol):
    s = Session.create(vol, intent=_intent(), settings=RunSettings(**SETTINGS))
    s.run(write_outputs=False)
    # Make the runner-up a twin of the winner that differs only in a hidden feature.
    top, second = s.last_ranking[:2]
    tf = s.tfs[top]
    gs = list(tf.gaussians)
    gs[0] = replace(gs[0], height=0.0)
    twin = tf.with_gaussians(gs)
    gs[0] = replace(gs[0], color=(0.0, 1.0, 0.0), mean=0.05)
    s.tfs[top], s.tfs[second] = twin, tf.with_gaussians(gs)
    s._images.pop(top, None), s._images.pop(second, None)
    plain = s.best(4, distinct=False)
    assert [t for t, _ in plain] == [s.tfs[c] for c in s.last_ranking[:4]]
    best = s.best(4)
    assert len(best) == 4 and best[0][0] == twin and s.tfs[second] not in [t for t, _ in best]
    pictures = [s.render(t, size=64).astype(float) for t, _ in best]
    for i in range(4):
        for j in range(i):
            assert np.abs(pictures[i] - pictures[j]).mean() >= 1.0
    s.close()
