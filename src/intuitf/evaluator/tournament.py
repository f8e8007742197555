"""Swiss-system tournament with Elo ratings: pairwise verdicts in, a ranking out.

The paper's scheme: everyone starts at the same rating (1600), ``ceil(log2 n) + 2`` rounds, a
random first round, then each round pairs players of nearest rating who have not met yet; every
match updates the Elo ratings of both players with K = 32. All matches of a round are judged
concurrently (``asyncio.gather`` over ``judge.compare``).

Two protocols share this code:

``"paper"``
    Ratings reset every tournament (any ``prior`` is ignored), the final order is the Elo order.
    With a judge that asks both orders of each pair (``MLLMJudge(swap="always")``) and
    ``rounds=floor(log2 n) + 2`` it spends what the authors' prototype spends (350 calls at n=50).

``"efficient"`` (the default)
    Made to spend fewer judge calls per ranking quality (``benchmarks/tournament.py`` measures
    it against the authors' protocol):

    - meant for a judge that asks once per pair (``MLLMJudge(swap="never")``): the tournament
      orients every match at random (seeded), which turns a judge's preference for one side
      into noise instead of a systematic error, and spends a second ask only where it matters:
      a decisive verdict that the ratings found surprising (its loser had at least
      ``recheck_above`` chance of winning) is asked again in the other order, and the two
      answers are averaged. Re-asks run concurrently with the next round, so they add at most
      one round trip to the tournament. (With ``swap="always"`` every pair costs two calls; with
      ``swap="auto"`` the judge fixes the order by content, so a re-ask repeats the same request
      and learns nothing new.) Unchanged pairs that meet again cost nothing when the judge
      caches verdicts;
    - the ranking, and the pairing from round 2 on, use a Bradley-Terry fit (minorise-maximise
      iteration) over *all* verdicts so far, regularised by ``anchor_weight`` virtual draws
      against a 1600 player, instead of the path-dependent Elo sum; ``ratings`` hold that fit
      on the Elo scale;
    - ``prior`` ratings (elites surviving from the last generation) seed the first round's
      pairing and the Elo start, but not the fit: anchoring survivors at their inflated ratings
      (they were chosen *because* they rated high) measurably lowered Kendall's tau;
    - ``history``, the verdicts of earlier tournaments under the same aspects and intent, joins
      the fit instead, each with the weight its caller gives it: a survivor keeps the evidence
      it earned (its rating is the fit of its games, not a number carried over). With a model
      judge the session fades a verdict by :data:`~intuitf.evaluator.ratings.HISTORY_FADE`
      per generation of age: at full weight, an early winner's lucky wins stayed in every
      later fit and it outranked newcomers that beat it head to head (a deterministic
      judge's verdicts keep full weight). Pairs that met in the history are not paired again
      (a cached judge would repeat its verdict, which is no new evidence).

Verdicts with ``p_first`` 0.5 (ties, or technical errors the judge reported as ties) score half a
point each and are recorded, so the same pair never meets twice in one tournament.

**One failed match never ends a tournament.** A match whose judge raises
:class:`~intuitf.errors.JudgeError` (the server gave no answer after its retries) is recorded as
an *undecided* match, a tie whose ``Verdict.error`` says why, exactly like an answer the judge
could not read, and the tournament goes on. Only when the judge is down, when more than half of
the requests of two rounds in a row got no answer (a server that is unreachable, rejects the
key, or stopped answering for longer than the answer deadline fails them all; one bad round of
a small field can be bad luck), does the tournament stop with a :class:`JudgeError` that says
so; the failed matches of that last round are then not recorded. Under the efficient
protocol an undecided match (no answer, or none usable) is asked once more, in the other order,
with the next round, and that answer stands in its place. Undecided matches are not cached, so
a resumed run asks them again. A re-ask that fails leaves its match's first verdict as it was. Results are
reproducible: with the same seed and the same verdicts the pairings and ratings are the same,
whatever order the concurrent matches finish in, because updates are applied in schedule order.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np

from intuitf.errors import IntuitfError, JudgeError
from intuitf.evaluator.matches import MatchRecord, MatchStats, TournamentResult
from intuitf.evaluator.ratings import bradley_terry, default_rounds, elo_expected, with_weights
from intuitf.evaluator.types import Aspect, Choice, Cost, Intent, Judge, Verdict, combine_answers

Protocol = Literal["efficient", "paper"]
ProgressFn = Callable[[int, int, int, Cost], None]
#: Called with each judged match, in schedule order, as soon as its round is scored.
MatchFn = Callable[["MatchRecord"], None]
#: An earlier verdict: (first id, second id, score of first[, weight in the fit]).
HistoryGame = tuple[str, str, float] | tuple[str, str, float, float]

#: The judge counts as down when more than this share of the requests of
#: ``JUDGE_DOWN_ROUNDS`` rounds in a row got no answer.
JUDGE_DOWN_SHARE = 0.5
JUDGE_DOWN_ROUNDS = 2

#: Beyond this many search steps the pairing gives up avoiding rematches (never reached in
#: practice: with log2(n) + 2 rounds each player has met only a handful of the others).
_PAIRING_STEP_LIMIT = 200_000

__all__ = [
    "MatchRecord",
    "MatchStats",
    "SwissTournament",
    "TournamentResult",
    "bradley_terry",
    "default_rounds",
    "elo_expected",
]


class SwissTournament:
    """Ranks images by pairwise verdicts of ``judge`` under ``aspects`` and ``intent``.

    ``rounds`` defaults to ``ceil(log2 n) + 2``. ``seed`` fixes the first-round draw, tie breaks
    and which image of each pair is shown first.
    """

    def __init__(
        self,
        judge: Judge,
        aspects: Sequence[Aspect],
        intent: Intent | None = None,
        *,
        seed: int = 0,
        k_factor: float = 32.0,
        initial_rating: float = 1600.0,
        rounds: int | None = None,
        protocol: Protocol = "efficient",
        anchor_weight: float = 3.0,
        recheck_above: float | None = 0.7,
    ) -> None:
        if protocol not in ("efficient", "paper"):
            raise IntuitfError(
                f"Unknown tournament protocol {protocol!r}.", hint="Use 'efficient' or 'paper'."
            )
        self.judge = judge
        self.aspects = list(aspects)
        self.intent = intent if intent is not None else Intent()
        self.seed = seed
        self.k_factor = float(k_factor)
        self.initial_rating = float(initial_rating)
        self.rounds = rounds
        self.protocol: Protocol = protocol
        #: Virtual drawn games against a 1600 player each player gets in the Bradley-Terry fit
        #: (regularisation; 3 ranked best in ``benchmarks/tournament.py``'s noisy setting).
        self.anchor_weight = float(anchor_weight)
        #: Efficient protocol: re-ask a decisive verdict in the other order when the rating fit
        #: gave its loser at least this chance of winning (None: never).
        self.recheck_above = recheck_above

    # ------------------------------------------------------------------ public

    async def run(
        self,
        images: Sequence[np.ndarray],
        ids: Sequence[str],
        prior: dict[str, float] | None = None,
        progress: ProgressFn | None = None,
        history: Sequence[HistoryGame] = (),
        on_match: MatchFn | None = None,
    ) -> TournamentResult:
        """Play the tournament and return ratings and ranking.

        ``history`` holds earlier verdicts as ``(first id, second id, score of first)``, or
        with a fourth element, the verdict's weight in the fit (a faded one from an earlier
        generation; see :data:`~intuitf.evaluator.ratings.HISTORY_FADE`); ids not among
        ``ids`` are past players. The efficient protocol fits them with this tournament's
        verdicts (see the module notes); the paper protocol ignores them.

        A match the judge fails with :class:`JudgeError` is recorded undecided and play goes on
        (see the module notes). If the judge raises :class:`BudgetExhausted`, or is down (more
        than half of the requests of two rounds in a row failed), the other matches of that round are awaited
        (they are paid for), and a :class:`BudgetExhausted` or :class:`JudgeError` is raised with
        an attribute ``partial``: the :class:`TournamentResult` of everything judged so far.
        """
        ids = [str(i) for i in ids]
        if len(images) != len(ids):
            raise IntuitfError(
                f"A tournament got {len(images)} images but {len(ids)} ids.",
                hint="Pass one id per image.",
            )
        if len(set(ids)) != len(ids):
            raise IntuitfError(
                "A tournament got duplicate ids.", hint="Give every candidate a unique id."
            )
        state = _State(self, images, ids, prior, progress, history)
        state.on_match = on_match
        return await state.play()

    def planned_rounds(self, n: int) -> int:
        """How many rounds a field of ``n`` plays."""
        if n < 2:
            return 0
        if self.rounds is not None:
            round_robin = n - 1 if n % 2 == 0 else n  # more rounds would force rematches
            return max(0, min(int(self.rounds), round_robin))
        return default_rounds(n)


class _State:
    """The mutable state of one tournament run."""

    def __init__(
        self,
        cfg: SwissTournament,
        images: Sequence[np.ndarray],
        ids: list[str],
        prior: dict[str, float] | None,
        progress: ProgressFn | None,
        history: Sequence[HistoryGame] = (),
    ) -> None:
        self.cfg = cfg
        self.images = images
        self.ids = ids
        self.n = len(ids)
        self.progress = progress
        self.rng = np.random.default_rng(cfg.seed)
        use_prior = cfg.protocol == "efficient" and prior
        self.start = np.array(
            [
                float(prior[i]) if use_prior and i in prior else cfg.initial_rating  # type: ignore[index]
                for i in ids
            ]
        )
        self.has_prior = np.array([bool(use_prior and i in prior) for i in ids])  # type: ignore[operator]
        self.elo = self.start.copy()
        # A fixed random order breaks rating ties, so equal ratings do not favour input order.
        self.tiebreak = self.rng.permutation(self.n)
        self.met: set[frozenset[int]] = set()
        #: Earlier verdicts with their weights, indexed over the current players followed by
        #: past ones.
        self.history: list[tuple[int, int, float, float]] = []
        self.n_players = self.n
        if cfg.protocol == "efficient" and history:
            index = {pid: i for i, pid in enumerate(ids)}
            for first, second, score, weight in with_weights(history):
                for pid in (str(first), str(second)):
                    if pid not in index:
                        index[pid] = len(index)
                i, j = index[str(first)], index[str(second)]
                if i == j:
                    continue
                self.history.append((i, j, min(1.0, max(0.0, score)), weight))
                if i < self.n and j < self.n:
                    self.met.add(frozenset((i, j)))
            self.n_players = len(index)
        self.had_bye: set[int] = set()
        self.matches: list[MatchRecord] = []
        self.games: list[tuple[int, int, float]] = []
        self.byes: list[tuple[int, str]] = []
        self.cost = Cost()
        self.rounds = cfg.planned_rounds(self.n)
        self.recheck_above = cfg.recheck_above if cfg.protocol == "efficient" else None
        #: Efficient protocol: an undecided match is asked once more, in the other order.
        self.reask_undecided = cfg.protocol == "efficient"
        #: Matches to re-ask in the other order: (index in matches, first, second).
        self.pending: list[tuple[int, int, int]] = []
        self.on_match: MatchFn | None = None
        #: Rounds in a row in which most requests got no answer.
        self.failing_rounds = 0
        self.t0 = time.perf_counter()

    async def play(self) -> TournamentResult:
        for rnd in range(1, self.rounds + 1):
            pairs, bye = self._pair(rnd)
            if bye is not None:
                self.had_bye.add(bye)
                self.byes.append((rnd, self.ids[bye]))
            # Orientation is drawn before any await, so it never depends on timing.
            flips = self.rng.random(len(pairs)) < 0.5
            oriented = [(q, p) if f else (p, q) for (p, q), f in zip(pairs, flips, strict=True)]
            await self._play_round(rnd, oriented)
        if self.pending:
            await self._play_round(self.rounds, [])  # the last round's re-asks
        return self._result(complete=True)

    # ------------------------------------------------------------ pairing

    def _order(self) -> list[int]:
        """Players sorted by current rating, best first, ties by the fixed random order.

        The efficient protocol sorts by the Bradley-Terry fit of all verdicts so far, which
        pairs players that are truly close more often than the path-dependent Elo sum does.
        """
        efficient = self.cfg.protocol == "efficient" and (self.games or self.history)
        rating = self._fit() if efficient else self.elo  # before any evidence: the priors
        return sorted(range(self.n), key=lambda i: (-rating[i], self.tiebreak[i]))

    def _fit(self) -> np.ndarray:
        # Priors are not anchors: survivors were picked for their (noisily) high rating, so
        # anchoring them there carries that winner's-curse bias into the new ranking; measured
        # in the benchmark, it lowered Kendall's tau. They only seed the first round's pairing.
        anchors = np.full(self.n_players, self.cfg.initial_rating)
        games: list = [*self.history, *self.games]
        return bradley_terry(self.n_players, games, anchors, self.cfg.anchor_weight)[: self.n]

    def _pair(self, rnd: int) -> tuple[list[tuple[int, int]], int | None]:
        if rnd == 1 and not (
            self.cfg.protocol == "efficient" and (self.has_prior.any() or self.history)
        ):
            order = list(self.rng.permutation(self.n))
        else:
            order = self._order()
        bye = None
        if len(order) % 2 == 1:
            # The lowest-placed player who has not sat out yet gets the bye.
            bye = next((p for p in reversed(order) if p not in self.had_bye), order[-1])
            order.remove(bye)
        if rnd == 1 and not self.met:
            return [(order[i], order[i + 1]) for i in range(0, len(order), 2)], bye
        pairs = self._pair_without_rematch(order)
        if pairs is None:
            pairs = self._pair_greedy(order)
        return pairs, bye

    def _pair_without_rematch(self, order: list[int]) -> list[tuple[int, int]] | None:
        """Nearest-rating pairing with no rematch; depth-first with backtracking."""
        steps = 0
        met = self.met

        def solve(rest: list[int]) -> list[tuple[int, int]] | None:
            nonlocal steps
            if not rest:
                return []
            p = rest[0]
            for j in range(1, len(rest)):
                steps += 1
                if steps > _PAIRING_STEP_LIMIT:
                    return None
                q = rest[j]
                if frozenset((p, q)) in met:
                    continue
                sub = solve(rest[1:j] + rest[j + 1 :])
                if sub is not None:
                    return [(p, q), *sub]
            return None

        return solve(order)

    def _pair_greedy(self, order: list[int]) -> list[tuple[int, int]]:
        """Fallback: pair each with the next unmet player, or the next one if all were met."""
        left = list(order)
        pairs = []
        while len(left) >= 2:
            p = left.pop(0)
            j = next((k for k, q in enumerate(left) if frozenset((p, q)) not in self.met), 0)
            pairs.append((p, left.pop(j)))
        return pairs

    # ------------------------------------------------------------ judging

    async def _play_round(self, rnd: int, pairs: list[tuple[int, int]]) -> None:
        """Judge a round's pairs, plus the re-asks scheduled by the round before, concurrently."""
        cfg = self.cfg
        checks, self.pending = self.pending, []
        done_before = len(self.matches)
        finished = 0
        fit_before = self._fit() if self.recheck_above is not None else None

        async def one(a: int, b: int) -> Verdict:
            nonlocal finished
            verdict = await cfg.judge.compare(
                self.images[a], self.images[b], cfg.aspects, cfg.intent
            )
            finished += 1
            if self.progress is not None:
                self.progress(rnd, self.rounds, done_before + finished, self.cost + verdict.cost)
            return verdict

        # A re-ask shows the pair in the other order: (b, a) for the match (a, b).
        jobs = [one(a, b) for a, b in pairs] + [one(b, a) for _, a, b in checks]
        outcomes = await asyncio.gather(*jobs, return_exceptions=True)
        failure: BaseException | None = None
        unanswered = [o for o in outcomes if isinstance(o, JudgeError)]
        if outcomes and len(unanswered) > JUDGE_DOWN_SHARE * len(outcomes):
            self.failing_rounds += 1
        else:
            self.failing_rounds = 0
        # One bad round can be bad luck (a small field has few matches a round); two in a row
        # are a judge that is down.
        down = self.failing_rounds >= JUDGE_DOWN_ROUNDS
        if down:
            failure = _judge_down(rnd, len(unanswered), len(outcomes), unanswered[-1])
        # Apply in schedule order, from the ratings at the start of the round: every player
        # plays at most once per round, so this equals sequential Elo and ignores timing.
        deltas = np.zeros(self.n)
        for (a, b), out in zip(pairs, outcomes[: len(pairs)], strict=True):
            if isinstance(out, JudgeError) and not down:
                # One match without an answer is an undecided match, not the end of the run.
                out = _undecided(out, cfg.aspects)
            if isinstance(out, BaseException):
                failure = failure or out
                continue
            s = min(1.0, max(0.0, float(out.p_first)))
            e = elo_expected(self.elo[a], self.elo[b])
            deltas[a] += cfg.k_factor * (s - e)
            deltas[b] -= cfg.k_factor * (s - e)
            self.met.add(frozenset((a, b)))
            self.games.append((a, b, s))
            self.cost += out.cost
            self.matches.append(MatchRecord(rnd, self.ids[a], self.ids[b], out))
            if self.on_match is not None:
                self.on_match(self.matches[-1])
            if self.reask_undecided and not out.decided:
                # No usable answer (or none at all): ask once more, in the other order (a new
                # question, so no cache repeats the failure), with the next round.
                self.pending.append((len(self.matches) - 1, a, b))
            elif fit_before is not None and s in (0.0, 1.0):
                # A surprise (the fit gave the loser a good chance) is the verdict most likely
                # to be a judge error: ask it again in the other order next round.
                p_loser = elo_expected(fit_before[b], fit_before[a]) if s == 1.0 else (
                    elo_expected(fit_before[a], fit_before[b])
                )  # fmt: skip
                if p_loser >= self.recheck_above:
                    self.pending.append((len(self.matches) - 1, a, b))
        self.elo += deltas
        for (idx, _a, _b), out in zip(checks, outcomes[len(pairs) :], strict=True):
            if isinstance(out, JudgeError) and not down:
                continue  # the match keeps its first verdict
            if isinstance(out, BaseException):
                failure = failure or out
                continue
            rec = self.matches[idx]
            if rec.verdict.decided:
                rec.verdict = _merge(rec.verdict, out.swapped(), cfg.aspects)
            else:  # the first ask told nothing: the second answer stands alone
                rec.verdict = _instead(rec.verdict, out.swapped())
            rec.rechecked = True
            i, j, _ = self.games[idx]
            self.games[idx] = (i, j, min(1.0, max(0.0, float(rec.verdict.p_first))))
            self.cost += out.cost
        if self.progress is not None:
            self.progress(rnd, self.rounds, len(self.matches), self.cost)
        if failure is not None:
            # BudgetExhausted and JudgeError are the expected ones; any exception gets the
            # partial result, so no paid verdict is lost whatever went wrong.
            try:
                failure.partial = self._result(complete=False)  # type: ignore[attr-defined]
            except AttributeError:  # an exception type that refuses new attributes
                pass
            raise failure

    # ------------------------------------------------------------ result

    def _result(self, complete: bool) -> TournamentResult:
        elo = {pid: float(r) for pid, r in zip(self.ids, self.elo, strict=True)}
        if self.cfg.protocol == "efficient" and self.n:
            final = self._fit()
        else:
            final = self.elo.copy()
        ratings = {pid: float(r) for pid, r in zip(self.ids, final, strict=True)}
        order = sorted(range(self.n), key=lambda i: (-final[i], -self.elo[i], self.tiebreak[i]))
        return TournamentResult(
            ratings=ratings,
            ranking=[self.ids[i] for i in order],
            matches=list(self.matches),
            cost=Cost(**self.cost.__dict__),
            rounds=self.rounds,
            wall_seconds=time.perf_counter() - self.t0,
            elo=elo,
            byes=list(self.byes),
            protocol=self.cfg.protocol,
            complete=complete,
        )


def _undecided(exc: JudgeError, aspects: Sequence[Aspect]) -> Verdict:
    """The verdict of a match the judge could not answer: a tie that says why (undecided)."""
    reason = getattr(exc, "message", None) or str(exc) or type(exc).__name__
    return Verdict(
        per_aspect={a.key: Choice.TIE for a in aspects},
        overall=Choice.TIE,
        p_first=0.5,
        error=f"no answer: {reason}",
    )


def _judge_down(rnd: int, failed: int, asked: int, last: JudgeError) -> JudgeError:
    """The error that stops a tournament whose judge answers (almost) nothing."""
    reason = getattr(last, "message", None) or str(last)
    return JudgeError(
        f"The judge is down: {failed} of {asked} requests of round {rnd} got no answer, as "
        f"did most of the round before (last: {reason}).",
        getattr(last, "hint", None)
        or "Check the model server; continue with `intuitf optimize --resume RUN`.",
    )


def _instead(undecided: Verdict, answer: Verdict) -> Verdict:
    """``answer`` in place of an undecided verdict, carrying what both cost."""
    errors = [e for e in (undecided.error, answer.error) if e]
    return Verdict(
        per_aspect=dict(answer.per_aspect),
        overall=answer.overall,
        p_first=answer.p_first,
        cost=undecided.cost + answer.cost,
        rationale=dict(answer.rationale),
        cached=undecided.cached and answer.cached,
        error="; ".join(errors) if answer.error else None,
        retries=undecided.retries + answer.retries,
    )


def _merge(a: Verdict, b: Verdict, aspects: Sequence[Aspect]) -> Verdict:
    """Two verdicts on the same ordered pair, averaged per aspect (like asking both orders)."""
    overall, p, per = combine_answers([a.per_aspect, b.per_aspect], aspects)
    rationale = dict(a.rationale)
    for k, v in b.rationale.items():
        rationale[k] = f"{rationale[k]} | (other order) {v}" if k in rationale else v
    errors = [e for e in (a.error, b.error) if e]
    return Verdict(
        per_aspect=per,
        overall=overall,
        p_first=p,
        cost=a.cost + b.cost,
        rationale=rationale,
        cached=a.cached and b.cached,
        error="; ".join(errors) if len(errors) == 2 else None,
        retries=a.retries + b.retries,
    )
