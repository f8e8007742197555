"""A run whose generation's candidates the judge could not tell apart says so: in
best/summary.json, in the report and in the CLI's end-of-run lines."""

from __future__ import annotations

import json
from types import SimpleNamespace

from intuitf.evaluator.metric import MetricJudge
from intuitf.evaluator.types import Choice, Cost, Intent, Verdict
from intuitf.session import RunSettings, Session
from intuitf.session.outputs import indistinct_generations, indistinct_note
from intuitf.session.rundir import RunDirectory
from intuitf.volume.phantom import phantom

SMALL = dict(population=4, generations=2, image_size=32, output_size=32, top_k=1)
SENTENCE = "could not tell the candidates apart"


class TieJudge:
    """A judge that finds every pair alike."""

    name = "tie"

    async def compare(self, first, second, aspects, intent) -> Verdict:
        return Verdict({a.key: Choice.TIE for a in aspects}, Choice.TIE, 0.5, cost=Cost(calls=1))


def run(tmp_path, judge, generations=2):
    out = tmp_path / "run"
    settings = RunSettings(**{**SMALL, "generations": generations})
    with Session.create(phantom(24), intent=Intent(kind="text", text="red bone"), judge=judge,
                        settings=settings, run_dir=out) as s:  # fmt: skip
        s.run(write_outputs=True)
    return out


def test_the_sentence_names_the_generations():
    gens = [{"generation": 0, "indistinct": True}, {"generation": 1, "indistinct": False},
            {"generation": 2, "match_stats": {"indistinct": 1}}]  # fmt: skip
    assert indistinct_generations(gens) == [0, 2]
    assert "generations 0, 2" in indistinct_note(gens) and SENTENCE in indistinct_note(gens)
    assert indistinct_note(gens[1:2]) == ""


def test_summary_report_and_cli_say_so(tmp_path, capsys):
    from intuitf.cli import optimize_cmds

    root = run(tmp_path, TieJudge())
    rd = RunDirectory(root)
    summary = json.loads(rd.best_summary.read_text())
    assert summary["indistinct_generations"] == [0, 1]
    assert any(SENTENCE in n for n in summary["notes"])
    assert summary["best"][0]["rank"] == 1
    page = (root / "report.html").read_text()
    assert SENTENCE in page and "generations 0, 1" in page
    optimize_cmds._print_match_stats(SimpleNamespace(run_dir=root))
    assert SENTENCE in capsys.readouterr().out


def test_a_judge_that_tells_them_apart_says_nothing(tmp_path, capsys):
    from intuitf.cli import optimize_cmds

    root = run(tmp_path, MetricJudge(), generations=1)
    summary = json.loads(RunDirectory(root).best_summary.read_text())
    assert summary["indistinct_generations"] == [] and summary["notes"] == []
    assert SENTENCE not in (root / "report.html").read_text()
    optimize_cmds._print_match_stats(SimpleNamespace(run_dir=root))
    assert SENTENCE not in capsys.readouterr().out
