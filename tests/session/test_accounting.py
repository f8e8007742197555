"""The journal's figures add up to what was paid, across a kill between a generation's journal
entry and its checkpoint, and with requests in flight at the kill."""

from __future__ import annotations

import numpy as np
import pytest

from intuitf.evaluator.cache import VerdictCache
from intuitf.session import Session
from intuitf.session.rundir import RunDirectory
from intuitf.session.store import RunStore
from intuitf.testing.fake_mllm import FakeMLLMServer
from intuitf.volume import phantom


class Killed(Exception):
    """Stands for a kill -9 right after the journal write."""


def test_figures_count_what_was_paid_across_a_kill(tmp_path, monkeypatch):
    vol = phantom(size=32)
    run = tmp_path / "runs" / "r"
    with FakeMLLMServer(target=np.full((32, 32, 3), 200, np.uint8), latency=0.0) as srv:
        spec = {"volume": "phantom", "intent": "bright bone",
                "settings": {"population": 6, "generations": 3, "seed": 4, "image_size": 32,
                             "output_size": 32, "top_k": 1},
                "judge": {"spec": srv.base_url, "options": {"max_retries": 0}}}  # fmt: skip
        s = Session.open(spec, run, volume=vol)
        s.step()  # generation 0, journaled and checkpointed
        real = Session._checkpoint

        def killed(self):
            raise Killed

        monkeypatch.setattr(Session, "_checkpoint", killed)
        with pytest.raises(Killed):
            s.step()  # generation 1 journaled, never checkpointed
        monkeypatch.setattr(Session, "_checkpoint", real)
        s.close()
        # One more request was under way when the process died: sent, never settled.
        other = VerdictCache(run / "verdicts.sqlite")
        other.begin_spend("url:default", 0.0)
        other.close()

        with Session.resume(run, volume=vol) as again:
            out = again.run(write_outputs=True)
        assert out.completed
        answered = srv.stats.answered

    rd = RunDirectory(run)
    raw = [e["generation"] for e in rd.read_journal() if e["type"] == "generation"]
    assert raw == [0, 1, 2]  # generation 1 was replayed after the kill: its entry replaced
    gens = rd.generations()
    assert [e["generation"] for e in gens] == [0, 1, 2]
    # The replayed generation's figures hold what its killed attempt paid (its answers are
    # cached, so the replay itself paid almost nothing) and the request in flight.
    journal_calls = sum(int(e["calls"]) for e in gens)
    assert journal_calls == answered + 1 == out.cost.calls
    assert gens[1]["calls"] > 1
    history = RunStore(run.parent).history("r")
    assert sum(h["calls"] for h in history) == journal_calls


def test_a_replayed_generation_replaces_its_journal_entries(tmp_path):
    rd = RunDirectory(tmp_path)
    rd.append_journal({"type": "run", "seed": 1})
    rd.append_journal({"type": "generation", "generation": 0, "calls": 5})
    rd.append_journal({"type": "verdict", "generation": 1, "a": 1})
    rd.append_journal({"type": "generation", "generation": 1, "calls": 4})
    rd.append_journal({"type": "generation", "generation": 2, "calls": 3})
    before = rd.journal.read_bytes()
    rd.append_journal({"type": "verdict", "generation": 3})  # no rewrite for other entries
    assert rd.journal.read_bytes().startswith(before)

    rd.append_journal({"type": "generation", "generation": 1, "calls": 9})  # replayed
    entries = rd.read_journal()
    assert [(e["type"], e.get("generation")) for e in entries] == [
        ("run", None), ("generation", 0), ("verdict", 1), ("verdict", 3), ("generation", 1),
    ]  # fmt: skip
    assert entries[-1]["calls"] == 9
