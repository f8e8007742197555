"""Session hooks: judge middleware and render timing, so code that drives a session (batch)
never patches its instance."""

from __future__ import annotations

from intuitf.session import RunSpec, Session
from intuitf.volume.phantom import phantom

SMALL = {"population": 6, "generations": 2, "image_size": 32, "output_size": 32, "top_k": 1}


class CountingJudge:
    """Middleware: counts the comparisons that pass through it."""

    def __init__(self, judge) -> None:
        self._judge = judge
        self.calls = 0
        self.name = getattr(judge, "name", "judge")

    async def compare(self, first, second, aspects, intent):
        self.calls += 1
        return await self._judge.compare(first, second, aspects, intent)

    def __getattr__(self, name):
        return getattr(self._judge, name)


def test_judge_middleware_sees_every_match_and_render_hooks_time_every_render():
    spec = RunSpec.model_validate({"volume": {"source": "phantom"}, "settings": SMALL})
    s = Session.open(spec, None, volume=phantom(32))
    wrapped: list[CountingJudge] = []
    original = s.judge

    def wrap(judge):
        wrapped.append(CountingJudge(judge))
        return wrapped[-1]

    s.add_judge_middleware(wrap)
    renders: list[float] = []
    remove = s.on_render(renders.append)
    matches = []
    s.events.subscribe(lambda e: matches.append(e) if e.type == "match_judged" else None)
    s.step()
    assert len(wrapped) == 1 and wrapped[0]._judge is original
    assert wrapped[0].calls == len(matches) > 0
    assert s.judge is original  # the session's own judge is not replaced
    # The sample cache and one picture per candidate, each timed.
    assert len(renders) == 1 + SMALL["population"] and all(t >= 0 for t in renders)
    assert sum(renders) > 0
    remove()
    s.step()
    assert len(renders) == 1 + SMALL["population"]  # removed: not called again
    assert len(wrapped) == 2 and wrapped[1].calls > 0
    s.close()


def test_a_run_in_memory_records_its_journal_and_checkpoints():
    from intuitf.session.recorder import MemoryRecorder

    spec = RunSpec.model_validate({"volume": {"source": "phantom"}, "settings": SMALL})
    s = Session.open(spec, None, volume=phantom(32))
    assert isinstance(s.recorder, MemoryRecorder) and s.recorder.events_path is None
    s.run(write_outputs=False)
    gens = [e for e in s.recorder.entries if e["type"] == "generation"]
    assert [e["generation"] for e in gens] == [0, 1]
    assert gens[-1]["candidates"] and gens[-1]["best_id"] == s.last_ranking[0]
    assert s.recorder.entries[-1]["type"] == "end"
    assert s.recorder.checkpoints == [1, 2]
    assert s.recorder.last_checkpoint["generation"] == 2
    assert s.recorder.last_checkpoint["ranking"] == s.last_ranking
