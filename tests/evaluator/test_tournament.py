"""Swiss-Elo tournament: pairing rules, Elo updates, reproducibility, ranking quality, failures."""

from __future__ import annotations

import asyncio
import math
import random
from collections import Counter

import numpy as np
import pytest
from scipy.stats import kendalltau

from intuitf.errors import BudgetExhausted
from intuitf.evaluator.ratings import HISTORY_FADE, faded
from intuitf.evaluator.tournament import (
    SwissTournament,
    TournamentResult,
    bradley_terry,
    default_rounds,
)
from intuitf.evaluator.types import Aspect, Choice, Cost, Intent, Verdict

ASPECTS = [Aspect("quality", "Quality", "overall quality")]


def img(q: int) -> np.ndarray:
    """An image whose hidden quality is its pixel value."""
    return np.full((4, 4, 3), q, dtype=np.uint8)


def quality(image: np.ndarray) -> int:
    return int(image[0, 0, 0])


class OracleJudge:
    """Prefers the higher quality; flips a seeded coin per pair with probability ``noise``."""

    name = "oracle"

    def __init__(self, noise: float = 0.0, ties_below: int = 0, delay: float = 0.0) -> None:
        self.noise = noise
        self.ties_below = ties_below
        self.delay = delay
        self.calls: list[tuple[int, int]] = []

    async def compare(self, first, second, aspects, intent) -> Verdict:
        a, b = quality(first), quality(second)
        self.calls.append((a, b))
        if self.delay:
            # Finish in an order unrelated to the schedule.
            await asyncio.sleep(self.delay * random.random())
        if abs(a - b) <= self.ties_below:
            choice = Choice.TIE
        else:
            choice = Choice.FIRST if a > b else Choice.SECOND
            # The same pair always gets the same noise, whatever the call order.
            if random.Random(hash((min(a, b), max(a, b)))).random() < self.noise:
                choice = choice.swapped()
        return Verdict({"quality": choice}, choice, choice.score, cost=Cost(calls=1))


def run(t: SwissTournament, qualities, prior=None, **kw) -> TournamentResult:
    images = [img(q) for q in qualities]
    ids = [f"q{q}" for q in qualities]
    return asyncio.run(t.run(images, ids, prior=prior, **kw))


def shuffled(n: int, seed: int = 1) -> list[int]:
    qs = list(range(10, 10 + 5 * n, 5))
    random.Random(seed).shuffle(qs)
    return qs


@pytest.mark.parametrize("n,expected", [(2, 1), (3, 3), (8, 5), (32, 7), (50, 8), (33, 8)])
def test_rounds_count(n, expected):
    assert default_rounds(n) == expected
    res = run(SwissTournament(OracleJudge(), ASPECTS, protocol="paper"), shuffled(n))
    assert res.rounds == expected
    assert len({m.round for m in res.matches}) == expected
    assert len(res.matches) == expected * (n // 2)


def test_no_rematches_and_bye_for_odd_n():
    n = 33
    res = run(SwissTournament(OracleJudge(noise=0.2), ASPECTS, seed=3), shuffled(n))
    pairs = [frozenset((m.first, m.second)) for m in res.matches]
    assert len(pairs) == len(set(pairs))
    assert len(res.byes) == res.rounds
    assert len({pid for _, pid in res.byes}) == res.rounds  # nobody sits out twice
    for rnd in range(1, res.rounds + 1):
        players = [p for m in res.matches if m.round == rnd for p in (m.first, m.second)]
        bye = [pid for r, pid in res.byes if r == rnd]
        assert len(players) == len(set(players)) == n - 1
        assert bye[0] not in players


def test_reproducible_regardless_of_completion_order():
    qs = shuffled(24)
    a = run(SwissTournament(OracleJudge(noise=0.2, delay=0.01), ASPECTS, seed=7), qs)
    b = run(SwissTournament(OracleJudge(noise=0.2, delay=0.01), ASPECTS, seed=7), qs)
    c = run(SwissTournament(OracleJudge(noise=0.2), ASPECTS, seed=8), qs)
    key = [(m.round, m.first, m.second, m.verdict.overall) for m in a.matches]
    assert key == [(m.round, m.first, m.second, m.verdict.overall) for m in b.matches]
    assert a.ratings == b.ratings and a.ranking == b.ranking
    assert key != [(m.round, m.first, m.second, m.verdict.overall) for m in c.matches]


def test_elo_update_moves_winner_up_by_k_over_two():
    res = run(SwissTournament(OracleJudge(), ASPECTS, protocol="paper", rounds=1), [10, 20])
    assert res.elo["q20"] == pytest.approx(1616.0)
    assert res.elo["q10"] == pytest.approx(1584.0)
    assert res.ranking == ["q20", "q10"]


def test_ties_score_half_and_are_recorded():
    # Two equal-quality pairs: every meeting among {10, 11} or {30, 31} is a tie.
    judge = OracleJudge(ties_below=1)
    res = run(SwissTournament(judge, ASPECTS, protocol="paper", rounds=1, seed=0), [10, 11])
    assert res.matches[0].verdict.overall is Choice.TIE
    assert res.elo == {"q10": 1600.0, "q11": 1600.0}
    res = run(SwissTournament(judge, ASPECTS, protocol="paper", seed=0), [10, 11, 30, 31])
    pairs = [frozenset((m.first, m.second)) for m in res.matches]
    assert len(pairs) == len(set(pairs)) == 6  # 3 rounds round robin: the tie was not replayed


def test_tie_against_higher_rated_gains_points():
    t = SwissTournament(OracleJudge(ties_below=100), ASPECTS, protocol="paper", rounds=1)
    res = asyncio.run(t.run([img(1), img(2)], ["a", "b"]))
    assert res.elo["a"] == res.elo["b"] == 1600.0
    # With a prior the lower-rated one gains from a draw (efficient protocol carries priors).
    t = SwissTournament(OracleJudge(ties_below=100), ASPECTS, rounds=1)
    res = asyncio.run(t.run([img(1), img(2)], ["a", "b"], prior={"a": 1500.0, "b": 1700.0}))
    assert res.elo["a"] > 1500.0 and res.elo["b"] < 1700.0


@pytest.mark.parametrize("protocol", ["paper", "efficient"])
def test_oracle_ranks_nearly_perfectly(protocol):
    qs = shuffled(32, seed=2)
    res = run(SwissTournament(OracleJudge(), ASPECTS, protocol=protocol, seed=1), qs)
    tau = kendalltau([res.ratings[f"q{q}"] for q in qs], qs).statistic
    # 7 rounds of 16 matches cannot fully sort 32 players; Elo's path dependence costs more.
    assert tau > (0.88 if protocol == "efficient" else 0.75)
    assert res.ranking[0] in {f"q{max(qs)}", f"q{max(qs) - 5}"}


@pytest.mark.parametrize("protocol", ["paper", "efficient"])
def test_noisy_oracle_still_ranks_well(protocol):
    qs = shuffled(32, seed=4)
    taus = []
    for seed in range(3):
        res = run(
            SwissTournament(OracleJudge(noise=0.1), ASPECTS, protocol=protocol, seed=seed), qs
        )
        taus.append(kendalltau([res.ratings[f"q{q}"] for q in qs], qs).statistic)
    assert np.mean(taus) > 0.65


def test_priors_seed_first_round_pairing_only_in_efficient_protocol():
    qs = shuffled(40, seed=5)
    top = sorted(qs)[-10:]
    prior = {f"q{q}": 1600.0 + 4 * (q - 100) for q in top}
    eff = run(SwissTournament(OracleJudge(), ASPECTS, seed=1), qs, prior=prior)
    assert eff.rounds == default_rounds(40)
    # Round 1 pairs by prior rating: the prior-rated elites meet each other.
    first = [m for m in eff.matches if m.round == 1]
    elite = {f"q{q}" for q in top}
    assert sum(1 for m in first if m.first in elite and m.second in elite) == 5
    paper = run(SwissTournament(OracleJudge(), ASPECTS, protocol="paper", seed=1), qs, prior=prior)
    first = [m for m in paper.matches if m.round == 1]
    assert sum(1 for m in first if m.first in elite and m.second in elite) < 5
    assert all(abs(paper.elo[k] - 1600) <= 16 * paper.rounds for k in paper.elo)


class BiasedJudge(OracleJudge):
    """Right on every pair, except that it always prefers q55 when shown first (a bias)."""

    async def compare(self, first, second, aspects, intent) -> Verdict:
        if quality(first) == 55:
            self.calls.append((55, quality(second)))
            return Verdict({"quality": Choice.FIRST}, Choice.FIRST, 1.0, cost=Cost(calls=1))
        return await super().compare(first, second, aspects, intent)


def test_surprising_verdicts_are_asked_again_in_the_other_order():
    qs = shuffled(16, seed=3)
    judge = BiasedJudge()
    res = run(SwissTournament(judge, ASPECTS, seed=2, recheck_above=0.6), qs)
    rechecked = [m for m in res.matches if m.rechecked]
    assert rechecked, "an upset by a weak player should be re-asked"
    assert res.cost.calls == len(res.matches) + len(rechecked)
    for m in rechecked:
        assert m.verdict.cost.calls == 2
        # The re-ask showed the pair the other way round.
        assert (quality(img(int(m.second[1:]))), quality(img(int(m.first[1:])))) in judge.calls
    off = run(SwissTournament(BiasedJudge(), ASPECTS, seed=2, recheck_above=None), qs)
    assert not any(m.rechecked for m in off.matches)
    assert off.cost.calls == len(off.matches)


def test_bradley_terry_recovers_strengths():
    rng = np.random.default_rng(0)
    true = np.linspace(1400, 1800, 12)
    games = []
    for _ in range(4000):
        i, j = rng.choice(12, 2, replace=False)
        p = 1 / (1 + 10 ** ((true[j] - true[i]) / 400))
        games.append((int(i), int(j), float(rng.random() < p)))
    fit = bradley_terry(12, games, np.full(12, 1600.0), 0.01)
    assert kendalltau(fit, true).statistic > 0.9
    assert np.ptp(fit) == pytest.approx(400, rel=0.2)


def test_a_weighted_game_counts_as_that_many_games():
    anchors = np.full(3, 1600.0)
    games = [(0, 1, 1.0), (1, 2, 1.0), (2, 0, 0.5), (0, 2, 1.0)]
    twice = bradley_terry(3, games + games[:2], anchors, 3.0)
    weighted = bradley_terry(3, [(0, 1, 1.0, 2.0), (1, 2, 1.0, 2.0), *games[2:]], anchors, 3.0)
    assert weighted == pytest.approx(twice, abs=1e-6)
    # Weight zero: as if the game was never played.
    none = bradley_terry(3, [*games[2:], (1, 0, 1.0, 0.0)], anchors, 3.0)
    assert none == pytest.approx(bradley_terry(3, games[2:], anchors, 3.0), abs=1e-6)


def test_faded_history_lets_a_newcomer_that_beat_the_early_winner_rank_first():
    # The early winner q50 beat five weak players in each of the four generations before;
    # the newcomer q60 beats it, and everyone else, in this one.
    qs = [20, 30, 50, 60]
    played = [("q50", f"old{g}-{k}", 1.0, g) for g in range(4) for k in range(5)]
    t = SwissTournament(OracleJudge(), ASPECTS, seed=0, rounds=3)
    res = run(t, qs, history=faded(played, 4))
    assert frozenset(("q50", "q60")) in {frozenset((m.first, m.second)) for m in res.matches}
    assert res.ranking[0] == "q60"
    # At full weight the old wins outrank the head-to-head loss: the pick sticks.
    assert run(t, qs, history=[g[:3] for g in played]).ranking[0] == "q50"
    # A generation's own verdicts count once, each one before by HISTORY_FADE less.
    assert [w for *_, w in faded(played[::5], 4)] == pytest.approx(
        [HISTORY_FADE**4, HISTORY_FADE**3, HISTORY_FADE**2, HISTORY_FADE]
    )


class FailingJudge(OracleJudge):
    """Raises ``exc`` on the call number ``fail_at`` (1-based); other calls answer normally."""

    def __init__(self, exc: Exception, fail_at: int) -> None:
        super().__init__(delay=0.005)
        self.exc = exc
        self.fail_at = fail_at
        self.answered = 0

    async def compare(self, first, second, aspects, intent) -> Verdict:
        self.calls.append((0, 0))
        if len(self.calls) == self.fail_at:
            await asyncio.sleep(0.001)
            raise self.exc
        self.calls.pop()
        v = await super().compare(first, second, aspects, intent)
        self.answered += 1
        return v


@pytest.mark.parametrize("exc", [BudgetExhausted("Budget spent.", hint="Raise it.")])
def test_failure_mid_round_keeps_every_paid_verdict(exc):
    # (A JudgeError on one match no longer stops the tournament: test_tournament_faults.py.)
    n = 16  # 8 matches a round; fail on the 3rd call of round 2
    judge = FailingJudge(exc, fail_at=11)
    t = SwissTournament(judge, ASPECTS, seed=0)
    with pytest.raises(type(exc)) as info:
        run(t, shuffled(n))
    partial = info.value.partial
    assert isinstance(partial, TournamentResult) and not partial.complete
    assert len(partial.matches) == judge.answered == 15
    assert Counter(m.round for m in partial.matches) == {1: 8, 2: 7}
    assert partial.cost.calls == 15
    assert len(partial.ranking) == n
    roundtrip = TournamentResult.from_dict(partial.to_dict())
    assert [m.verdict.overall for m in roundtrip.matches] == [
        m.verdict.overall for m in partial.matches
    ]


def test_progress_reports_every_match():
    seen = []
    res = run(
        SwissTournament(OracleJudge(), ASPECTS, seed=0),
        shuffled(10),
        progress=lambda r, total, done, cost: seen.append((r, total, done, cost.calls)),
    )
    assert seen[-1] == (res.rounds, res.rounds, len(res.matches), len(res.matches))
    assert max(d for _, _, d, _ in seen) == len(res.matches)


def test_rounds_run_concurrently():
    judge = OracleJudge()
    n = 20
    inflight = {"now": 0, "max": 0}

    async def compare(first, second, aspects, intent):
        inflight["now"] += 1
        inflight["max"] = max(inflight["max"], inflight["now"])
        await asyncio.sleep(0.01)
        inflight["now"] -= 1
        return await OracleJudge.compare(judge, first, second, aspects, intent)

    judge.compare = compare
    res = run(SwissTournament(judge, ASPECTS, seed=0), shuffled(n))
    assert inflight["max"] == n // 2
    assert res.rounds == math.ceil(math.log2(n)) + 2


def test_intent_defaults_and_duplicate_ids_rejected():
    from intuitf.errors import IntuitfError

    t = SwissTournament(OracleJudge(), ASPECTS)
    assert isinstance(t.intent, Intent)
    with pytest.raises(IntuitfError):
        asyncio.run(t.run([img(1), img(2)], ["a", "a"]))
    with pytest.raises(IntuitfError):
        SwissTournament(OracleJudge(), ASPECTS, protocol="fast")  # type: ignore[arg-type]


def test_history_joins_the_fit_and_met_pairs_are_not_replayed():
    qs = shuffled(16, seed=4)
    ids = [f"q{q}" for q in qs]
    worst = f"q{min(qs)}"
    # Earlier verdicts: the worst player beat six others (some of them past players, gone
    # now), and two current pairs already met.
    history = [(worst, f"old{k}", 1.0) for k in range(3)]
    history += [(worst, other, 1.0) for other in ids[:4] if other != worst][:3]
    met = {frozenset(p[:2]) for p in history}
    base = run(SwissTournament(OracleJudge(), ASPECTS, seed=3), qs)
    with_history = run(SwissTournament(OracleJudge(), ASPECTS, seed=3), qs, history=history)
    assert with_history.ratings[worst] > base.ratings[worst] + 50
    assert set(with_history.ratings) == set(ids)  # past players are fitted, not reported
    assert not any(frozenset((m.first, m.second)) in met for m in with_history.matches)
    # The paper protocol resets ratings every tournament: history changes nothing.
    paper = SwissTournament(OracleJudge(), ASPECTS, protocol="paper", seed=3)
    a, b = run(paper, qs), run(paper, qs, history=history)
    assert a.ranking == b.ranking and a.ratings == b.ratings


def test_history_keeps_a_survivor_from_sinking_on_one_bad_verdict():
    # The best player loses its one game of this tournament to a judge error; its twelve
    # earlier wins (against players that are still here) keep it on top.
    qs = [10, 20, 30, 40]
    ids = [f"q{q}" for q in qs]

    class OneError(OracleJudge):
        async def compare(self, first, second, aspects, intent):
            v = await super().compare(first, second, aspects, intent)
            if 40 in (quality(first), quality(second)):
                flipped = v.overall.swapped()
                return Verdict({"quality": flipped}, flipped, flipped.score, cost=Cost(calls=1))
            return v

    history = [("q40", other, 1.0) for other in ("p1", "p2", "p3", "p4") for _ in range(3)]
    t = SwissTournament(OneError(), ASPECTS, seed=0, rounds=1, recheck_above=None)
    assert run(t, qs).ranking[0] != "q40"
    assert run(t, qs, history=history).ranking[0] == "q40"
    assert set(ids) == set(run(t, qs, history=history).ranking)
