"""A subscriber that attaches after Session.open, without ``since``, still gets the session's
first event; one that attaches to a resumed run does not get earlier processes' events."""

from __future__ import annotations

from intuitf.session import Session

SPEC = {"volume": "phantom", "intent": "bone",
        "settings": {"population": 4, "generations": 2, "image_size": 32, "output_size": 32}}  # fmt: skip


def test_a_late_subscriber_gets_the_first_event(tmp_path):
    seen = []
    with Session.open(SPEC, tmp_path / "r") as s:
        s.events.subscribe(seen.append)
        assert [e.type for e in seen] == ["stage_started"] and seen[0].seq == 1
        s.step()
    assert [e.seq for e in seen] == list(range(1, len(seen) + 1))  # each once, in order

    later = []
    with Session.resume(tmp_path / "r") as s:
        s.events.subscribe(later.append)
        assert later == []  # the first process's events are history (since=0 replays them)
        history = []
        s.events.subscribe(history.append, since=0)
        assert history[0].seq == 1 and len(history) >= len(seen)
