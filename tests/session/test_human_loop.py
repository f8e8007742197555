"""The human-verdict loop on its own: a small host stands in for the Session (VerdictHost)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import pytest

from intuitf.errors import SessionError
from intuitf.explorer import make_explorer
from intuitf.session.human import HumanVerdict
from intuitf.session.human_loop import HumanVerdicts
from intuitf.tf import GaussianTF


@dataclass
class Host:
    """Just what the loop reads and re-ranks (the interface a Session offers it)."""

    explorer: Any
    last_ranking: list[str] = field(default_factory=list)
    ratings: dict[str, float] = field(default_factory=dict)
    plan: list[tuple[str, int]] = field(default_factory=lambda: [("initialize", 4)])
    stage_index: int = 0
    generation: int = 0
    tfs: dict[str, GaussianTF] = field(default_factory=dict)
    stepping: bool = False


def _judged_generation() -> tuple[Host, HumanVerdicts, list[tuple[str, HumanVerdict]]]:
    """A host after one generation ranked by 'the model' (ids in ask order, first best)."""
    import numpy as np

    explorer = make_explorer("ga", population=6, n_gaussians=3, generations=4, seed=3,
                             histogram=np.ones(256), value_range=(0.0, 255.0))  # fmt: skip
    host = Host(explorer=explorer)
    changes: list[tuple[str, HumanVerdict]] = []
    loop = HumanVerdicts(host, lambda action, v: changes.append((action, v)))
    candidates = explorer.ask()
    ids = [c.id for c in candidates]
    host.tfs = {c.id: c.tf for c in candidates}
    games = [(a, b, 1.0) for i, a in enumerate(ids) for b in ids[i + 1 :]]  # earlier beats later
    ratings = {cid: 1500.0 - 10 * i for i, cid in enumerate(ids)}
    ranking, ratings = loop.rank_generation(explorer.state_dict(), ids, ids, ratings, games, 0)
    assert ranking == ids  # no verdict of a person yet: the model's ranking stands as given
    explorer.tell(ranking)
    host.last_ranking, host.ratings, host.generation = ranking, ratings, 1
    return host, loop, changes


def test_a_verdict_re_tells_the_explorer_and_undo_restores_the_models_ranking():
    host, loop, changes = _judged_generation()
    model = list(host.last_ranking)
    told = host.explorer.state_dict()
    v = loop.add("prefer", [model[-1]], [model[0]], "the last one is better")
    assert host.last_ranking.index(model[-1]) < host.last_ranking.index(model[0])
    assert host.explorer.state_dict() != told  # a new Explorer, told the new ranking
    assert changes == [("added", v)]
    assert v.stage_index == 0 and v.generation == 1 and v.note == "the last one is better"

    loop.undo()
    assert v.undone and host.last_ranking == model
    assert host.explorer.state_dict() == told  # re-told from its state before the first tell
    assert [a for a, _ in changes] == ["added", "undone"]
    with pytest.raises(SessionError, match="no verdict"):
        loop.undo()


def test_while_a_generation_is_judged_only_the_shown_ranking_is_refitted():
    host, loop, _ = _judged_generation()
    model, explorer = list(host.last_ranking), host.explorer
    host.stepping = True
    loop.add("best", [model[-1]], model[:-1], "")
    assert host.last_ranking[0] == model[-1]
    assert host.explorer is explorer  # it hears the verdict when that generation ends
    assert loop.games(0)  # ... through the stage's games the next tournament fits


def test_unknown_or_empty_choices_are_refused_and_nothing_changes():
    host, loop, changes = _judged_generation()
    with pytest.raises(SessionError, match="Cannot judge"):
        loop.add("prefer", ["g999-000"], [host.last_ranking[0]], "")
    with pytest.raises(SessionError):
        loop.add("worst", [], [host.last_ranking[0]], "")
    assert loop.verdicts == [] and changes == []


def test_its_checkpoint_state_restores_an_equal_loop():
    host, loop, _ = _judged_generation()
    loop.add("prefer", [host.last_ranking[-1]], [host.last_ranking[0]], "")
    state = loop.state()
    again = HumanVerdicts(host, lambda *_: None)
    again.restore(state)
    assert again.state() == state
    assert again.refit() == loop.refit()


def test_a_persons_verdict_enters_the_fit_once_with_its_weight():
    """One game per stated pair, weighted :data:`HUMAN_WEIGHT`: the fit ranks as if it were
    that many model verdicts, and an undone or other-stage verdict adds nothing."""
    from intuitf.session.human import HUMAN_WEIGHT, refit_ranking, weighted_games

    ids = ["a", "b", "c"]
    # The model's record: a beat b three times, b beat c three times, c beat a once.
    model = [("a", "b", 1.0)] * 3 + [("b", "c", 1.0)] * 3 + [("c", "a", 1.0)]
    said = HumanVerdict(1, "prefer", ["c"], ["b"], generation=0, stage_index=0)
    other = HumanVerdict(2, "prefer", ["b"], ["a"], generation=0, stage_index=1)
    undone = HumanVerdict(3, "prefer", ["b"], ["a"], generation=0, stage_index=0, undone=True)
    games = weighted_games([said, other, undone], 0)
    assert games == [("c", "b", 1.0, float(HUMAN_WEIGHT))]
    order, rating = refit_ranking(ids, model + games)
    repeated, by_copies = refit_ranking(ids, model + [("c", "b", 1.0)] * HUMAN_WEIGHT)
    assert order == repeated
    assert all(abs(rating[k] - by_copies[k]) < 1e-6 for k in ids)
    # And it weighs more than one model verdict: c passes b when a person says so, not when
    # one more model verdict does.
    assert order.index("c") < order.index("b")
    one_more = refit_ranking(ids, model + [("c", "b", 1.0)])[0]
    assert one_more.index("c") > one_more.index("b")
