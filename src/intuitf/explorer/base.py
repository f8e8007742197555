"""What every explorer shares: the ask/tell contract, ids, stage bookkeeping and state."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from intuitf.explorer.bounds import Bounds
from intuitf.explorer.candidate import Candidate, candidate_id
from intuitf.explorer.fitness import rank_fitness
from intuitf.explorer.genome import is_duplicate_of_any
from intuitf.explorer.hints import (
    Hint,
    as_hints,
    as_the_words_say,
    from_strokes,
    hint_color,
    hint_for,
    hinted_tf,
    placed_hints,
)
from intuitf.explorer.operators import MutationParams, mutate
from intuitf.explorer.population import materials_of, random_tf, seeded_tf
from intuitf.explorer.stages import STAGES, StagePreset
from intuitf.tf.gaussian import MAX_GAUSSIANS, MIN_GAUSSIANS, GaussianTF

STATE_FORMAT = "intuitf.explorer-state"
STATE_VERSION = 1


def rng_state(rng: np.random.Generator) -> dict:
    """The generator's full state, as plain JSON-able values."""
    return rng.bit_generator.state


def rng_from_state(state: dict) -> np.random.Generator:
    bg_cls = getattr(np.random, state["bit_generator"])
    bg = bg_cls()
    bg.state = state
    return np.random.Generator(bg)


def _palette(colours: Sequence[Sequence[float]]) -> tuple[tuple[float, float, float], ...]:
    out = []
    for c in colours:
        rgb = tuple(float(v) for v in c)
        if len(rgb) != 3 or not all(0.0 <= v <= 1.0 for v in rgb):
            raise ValueError(f"A palette colour must be three values in [0, 1], got {c!r}.")
        out.append(rgb)
    return tuple(out)  # type: ignore[return-value]


class BaseExplorer:
    """Ask/tell skeleton: ``ask()`` gives the population, ``tell(ranking)`` moves on.

    Arguments (keyword only):
        population: candidates per generation (constant).
        n_gaussians: Gaussians per fresh TF (given ``initial`` TFs keep their own count).
        generations: planned generations of the first stage (the schedules run over them).
        stage: "initialize", "customize", "refine" (names in ``presets``) or a StagePreset.
        seed: seeds the run's only random generator; same seed + same rankings = same run.
        histogram: counts over [0, 1] (``Volume.histogram()[0]``); fresh populations then
            place a share of TFs on the volume's materials.
        value_range: original data units, recorded in every TF made.
        initial: TFs included as-is in the first population (branching from earlier
            results); the bounds widen to hold them. At most ``population`` are used.
        bounds: where parameters may go (:class:`Bounds`; default: normalised defaults).
        presets: the stage presets the names resolve to (default :data:`STAGES`).
        palette: RGB colours (0..1) the intent asks for (see
            :func:`intuitf.intent.palette.intent_palette`); the stage presets say how
            often new colours come from it. Empty: colours come from the whole colour space.
        hints: materials the intent names, each with where it sits, its colour and opacity
            (:class:`~intuitf.explorer.hints.Hint` or its dict; see
            :func:`intuitf.intent.hints.explorer_hints`). ``hint_share`` of a fresh
            population is placed on them, and mutations draw a Gaussian's colour and height
            from its material's hint now and then (``hint_prob``). Empty: no hints.

    Subclasses implement :meth:`_next_population` (and may extend state and stages).
    Generations are counted over the whole run; ``progress`` restarts at each stage.
    """

    method = "base"

    def __init__(
        self,
        *,
        population: int = 50,
        n_gaussians: int = 5,
        generations: int = 15,
        stage: str | StagePreset = "initialize",
        seed: int = 0,
        histogram: np.ndarray | None = None,
        value_range: tuple[float, float] | None = None,
        initial: Sequence[GaussianTF] = (),
        bounds: Bounds | None = None,
        presets: Mapping[str, StagePreset] | None = None,
        palette: Sequence[Sequence[float]] = (),
        hints: Sequence[Hint | Mapping] = (),
    ) -> None:
        if int(population) < 2:
            raise ValueError(f"population must be at least 2, got {population}.")
        if not MIN_GAUSSIANS <= int(n_gaussians) <= MAX_GAUSSIANS:
            raise ValueError(f"n_gaussians must be within [{MIN_GAUSSIANS}, {MAX_GAUSSIANS}].")
        if int(generations) < 1:
            raise ValueError(f"generations must be at least 1, got {generations}.")
        self.population_size = int(population)
        self.n_gaussians = int(n_gaussians)
        self.seed = int(seed)
        self.value_range = tuple(float(v) for v in value_range) if value_range else None
        self.palette = _palette(palette)
        self.hints = as_hints(hints)
        initial = list(initial)[: self.population_size]
        self.bounds = (bounds or Bounds()).covering(initial)
        self.presets: dict[str, StagePreset] = dict(presets or STAGES)
        self._preset = self._resolve(stage)
        self._stage_generations = int(generations)
        self._rng = np.random.default_rng(self.seed)
        self._generation = 0
        self._stage_start = 0
        self._counter = 0
        self._history: list[str] = []
        self._best: Candidate | None = None
        self._population: list[Candidate] = []
        self._materials = materials_of(histogram, self.n_gaussians)
        self._population = self._fresh_population(initial)

    # -- public read-only state ------------------------------------------------------------
    @property
    def generation(self) -> int:
        """Index of the population ``ask()`` returns (0 for the first)."""
        return self._generation

    @property
    def generations(self) -> int:
        """Planned number of generations of the current stage."""
        return self._stage_generations

    @property
    def progress(self) -> float:
        """How far the current stage is, 0 at its first generation and 1 at its last."""
        done = self._generation - self._stage_start
        return min(1.0, done / max(1, self._stage_generations - 1))

    @property
    def stage(self) -> StagePreset:
        return self._preset

    @property
    def aspects(self) -> str:
        """The aspect set ("quality", "intent" or "edit") the current stage is judged on."""
        return self._preset.aspects

    @property
    def best(self) -> Candidate | None:
        """The top candidate of the last ``tell`` (None before the first)."""
        return self._best

    @property
    def population(self) -> list[Candidate]:
        return list(self._population)

    @property
    def history(self) -> list[str]:
        """Id of the best candidate of each told generation, in order."""
        return list(self._history)

    @property
    def done(self) -> bool:
        """Whether the current stage has run its planned generations (the Explorer protocol)."""
        return self.finished

    @property
    def finished(self) -> bool:
        """Whether the current stage has run its planned generations."""
        return self._generation - self._stage_start >= self._stage_generations

    # -- ask / tell ------------------------------------------------------------------------
    def ask(self) -> list[Candidate]:
        """The candidates to render and rank; the same list until ``tell`` is called."""
        return list(self._population)

    def tell(self, ranking: Sequence[str], fitness: Sequence[float] | None = None) -> None:
        """Report the ranking (candidate ids, best first) of the population from ``ask``.

        ``fitness`` (aligned with ``ranking``) defaults to the rank fitness of the stage's
        pressure schedule at the current progress. Builds the next population.
        """
        ranked = self._ranked(ranking)
        n = len(ranked)
        if fitness is None:
            fit = rank_fitness(n, self.progress, self._preset.pressure)
        else:
            fit = np.asarray(fitness, dtype=np.float64)
            if fit.shape != (n,) or not np.isfinite(fit).all() or (fit < 0).any():
                raise ValueError("fitness must hold one finite, non-negative value per ranked id.")
        progress = self.progress
        self._best = ranked[0]
        self._history.append(ranked[0].id)
        self._generation += 1
        self._counter = 0  # ids of the new generation's candidates start at 000
        self._population = self._next_population(ranked, fit, progress)

    def _ranked(self, ranking: Sequence[str]) -> list[Candidate]:
        by_id = {c.id: c for c in self._population}
        ids = [str(i) for i in ranking]
        if len(set(ids)) != len(ids):
            raise ValueError("The ranking names a candidate twice.")
        if set(ids) != set(by_id):
            missing = sorted(set(by_id) - set(ids))[:5]
            unknown = sorted(set(ids) - set(by_id))[:5]
            raise ValueError(
                f"The ranking must name every candidate of the current population once "
                f"(missing {missing}, unknown {unknown})."
            )
        return [by_id[i] for i in ids]

    def _next_population(
        self, ranked: list[Candidate], fitness: np.ndarray, progress: float
    ) -> list[Candidate]:
        """The population after ``ranked`` (best first), built at ``progress`` of the stage."""
        raise NotImplementedError

    # -- stages ----------------------------------------------------------------------------
    def _resolve(self, stage: str | StagePreset) -> StagePreset:
        if isinstance(stage, StagePreset):
            return stage
        if stage not in self.presets:
            raise ValueError(f"Unknown stage {stage!r}; choose one of {sorted(self.presets)}.")
        return self.presets[stage]

    def set_stage(
        self,
        stage: str | StagePreset,
        *,
        generations: int | None = None,
        selected: Sequence[int] = (),
        base: GaussianTF | None = None,
        joining: Sequence[GaussianTF] = (),
    ) -> None:
        """Move to another stage, keeping the population; the stage's progress restarts.

        A stage that freezes (refine) freezes every Gaussian but the indices ``selected`` in
        every individual; with ``base`` the population is rebuilt around that TF instead
        (it, as-is but frozen, plus variants of its selected Gaussians). Other stages
        unfreeze everything, and with material hints replace the population's last
        ``stage_hint_share`` (bred by roulette, not elites) by fresh hinted TFs; ``joining``
        TFs (a sketch's fitted TF) then take the last places as they are.
        """
        preset = self._resolve(stage)
        if generations is not None and int(generations) < 1:
            raise ValueError("generations must be at least 1.")
        sel = sorted({int(i) for i in selected})
        if preset.freeze_unselected:
            # Check everything before changing anything: a bad call leaves the run as it was.
            if not sel:
                raise ValueError("The refine stage needs at least one selected Gaussian index.")
            for tf in [base] if base is not None else [c.tf for c in self._population]:
                if sel[0] < 0 or sel[-1] >= len(tf):
                    raise ValueError(
                        f"Selected Gaussian indices {sel} out of range for {len(tf)} Gaussians."
                    )
        if generations is not None:
            self._stage_generations = int(generations)
        self._preset = preset
        self._stage_start = self._generation
        if base is not None:
            self.bounds = self.bounds.covering([base])
            start = base.freeze(sel) if preset.freeze_unselected else base.unfreeze()
            self._population = self._variants_of([start])
        elif preset.freeze_unselected:
            self._population = [self._retf(c, c.tf.freeze(sel)) for c in self._population]
        else:
            self._population = [self._retf(c, c.tf.unfreeze()) for c in self._population]
            self._bring_in_hints()
            joining = list(joining)[: len(self._population)]
            if joining:
                self.bounds = self.bounds.covering(joining)
                kept = self._population[: len(self._population) - len(joining)]
                self._population = kept + [self._new(tf, "initial") for tf in joining]

    def _hints_placed(self) -> bool:
        """Whether a hint sits somewhere on the values and shows (what hinted TFs are built
        from)."""
        return bool(placed_hints(self.hints))

    def _bring_in_hints(self) -> None:
        n = round(self._preset.stage_hint_share * len(self._population))
        if n < 1 or not self._hints_placed():
            return
        pop = self._population[: len(self._population) - n]
        for _ in range(n):
            pop.append(self._unique(self._hinted, "hint", pop))
        self._population = pop

    @staticmethod
    def _retf(c: Candidate, tf: GaussianTF) -> Candidate:
        # Only frozen flags differ: the rendering is the same, so the id stays.
        return c if tf == c.tf else Candidate(c.id, tf, c.generation, c.origin, c.parents)

    # -- making candidates -----------------------------------------------------------------
    def _new(self, tf: GaussianTF, origin: str, parents: Sequence[str] = ()) -> Candidate:
        cid = candidate_id(self._generation, self._counter)
        self._counter += 1
        if origin != "initial":
            # A made TF is named by its candidate id (exports and plots show it); the
            # parent's name and metadata would describe a different TF.
            tf = replace(tf, name=cid, metadata={})
            # What the words name and show stays shown (a judge of colours alone may fade it),
            # and what they hide stays hidden (the background: no fog).
            tf = as_the_words_say(tf, self.hints, self.bounds)
        return Candidate(cid, tf, self._generation, origin, tuple(parents))

    def _color(self, rng: np.random.Generator) -> tuple[float, float, float]:
        """A new Gaussian's colour: from the palette (``palette_share`` of the time) or anywhere."""
        # Without a palette no random number is spent, so such runs stay as they were.
        if self.palette and rng.random() < self._preset.palette_share:
            return self.bounds.sample_palette_color(rng, self.palette)
        return self.bounds.sample_color(rng)

    def _random(self) -> GaussianTF:
        return random_tf(
            self._rng,
            self.n_gaussians,
            self.bounds,
            sampling=self._preset.init_sampling,
            value_range=self.value_range,
            color=self._color,
        )

    def _hinted(self) -> GaussianTF:
        return hinted_tf(
            self._rng,
            self.hints,
            self._materials,
            self.n_gaussians,
            self.bounds,
            value_range=self.value_range,
            color=self._color,
        )

    def _seeded(self) -> GaussianTF:
        tf = seeded_tf(
            self._rng,
            self._materials,
            self.n_gaussians,
            self.bounds,
            value_range=self.value_range,
            color=self._color,
        )
        placed = [h for h in self.hints if h.center is not None and h.color is not None]
        if not placed:
            return tf
        # A Gaussian on a material the words give a colour takes that colour (mostly): a
        # palette colour on the wrong material (an ivory crown for "blue crown, ivory
        # dentin") looks as good to a judge that cannot tell a crown from a root.
        gs = list(tf.gaussians)
        for k, g in enumerate(gs):
            h = hint_for(g.mean, placed)
            if h is not None and self._rng.random() < self._preset.palette_share:
                gs[k] = replace(g, color=hint_color(self._rng, h.color, self.bounds))
        return tf.with_gaussians(gs)

    def _fresh_population(
        self, initial: Sequence[GaussianTF], size: int | None = None, keep: Sequence[Candidate] = ()
    ) -> list[Candidate]:
        """``initial`` as-is, variants of it, histogram seeds and random TFs, deduplicated.

        ``size`` candidates (default: the population size) are made, none a near-duplicate
        of ``keep`` or of each other. In a freezing stage only variants of ``initial`` are
        made (fresh TFs would ignore what is frozen).
        """
        n = self.population_size if size is None else int(size)
        pop: list[Candidate] = list(keep)
        made: list[Candidate] = []
        for tf in initial:
            if self._preset.dedup and is_duplicate_of_any(tf, [c.tf for c in pop]):
                continue
            c = self._new(tf, "initial")
            pop.append(c)
            made.append(c)
        if made:
            # Branching from earlier results: a third of the rest explores near them (all
            # of it in a freezing stage).
            n_var = n - len(made) if self._preset.freeze_unselected else (n - len(made)) // 3
            before = len(pop)
            pop = self._fill_with_variants(pop, len(pop) + n_var, parents=made)
            made += pop[before:]
        share = (
            self._preset.stroke_hint_share if from_strokes(self.hints) else self._preset.hint_share
        )
        n_hint = round(share * (n - len(made))) if self._hints_placed() else 0
        for _ in range(n_hint):
            c = self._unique(self._hinted, "hint", pop)
            pop.append(c)
            made.append(c)
        n_seed = round(self._preset.seed_share * n) if self._materials else 0
        for _ in range(min(n_seed, n - len(made))):
            c = self._unique(self._seeded, "seed", pop)
            pop.append(c)
            made.append(c)
        while len(made) < n:
            c = self._unique(self._random, "random", pop)
            pop.append(c)
            made.append(c)
        return made

    def _unique(self, make, origin: str, pop: list[Candidate]) -> Candidate:
        tf = make()
        if self._preset.dedup:
            for _ in range(20):
                if not is_duplicate_of_any(tf, [c.tf for c in pop]):
                    break
                tf = make()
        return self._new(tf, origin)

    def _variant_params(self) -> MutationParams:
        return self._preset.mutation_params(0.0, self.palette, self.hints)

    def _fill_with_variants(
        self, pop: list[Candidate], size: int, parents: Sequence[Candidate] | None = None
    ) -> list[Candidate]:
        """Append mutated copies of ``parents`` (default ``pop``; round robin) up to ``size``."""
        params = self._variant_params()
        k = 0
        base = list(parents if parents is not None else pop)
        while len(pop) < size:
            parent = base[k % len(base)]
            k += 1
            tf = mutate(parent.tf, self._rng, params, self.bounds)
            tf = self.dedup(tf, pop, params)
            pop.append(self._new(tf, "mutation", (parent.id,)))
        return pop

    def _variants_of(self, tfs: Sequence[GaussianTF]) -> list[Candidate]:
        pop = [self._new(tf, "initial") for tf in tfs]
        return self._fill_with_variants(pop, self.population_size)

    def dedup(self, tf: GaussianTF, pop: Sequence[Candidate], params: MutationParams) -> GaussianTF:
        """``tf``, or a nudged version of it if it nearly duplicates a member of ``pop``.

        A nudge mutates every attribute of one free Gaussian; after 20 nudges that still
        collide (nothing left free to vary) the duplicate is kept.
        """
        if not self._preset.dedup:
            return tf
        others = [c.tf for c in pop]
        free = [i for i, g in enumerate(tf.gaussians) if not g.frozen]
        for _ in range(20):
            if not free or not is_duplicate_of_any(tf, others):
                break
            i = free[int(self._rng.integers(len(free)))]
            tf = mutate(tf, self._rng, params.forced(), self.bounds, only=[i])
        return tf

    # -- state -----------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """The full state as JSON-serialisable values; see :meth:`from_state`."""
        return {
            "format": STATE_FORMAT,
            "version": STATE_VERSION,
            "method": self.method,
            "population_size": self.population_size,
            "n_gaussians": self.n_gaussians,
            "seed": self.seed,
            "value_range": list(self.value_range) if self.value_range else None,
            "bounds": self.bounds.to_dict(),
            "presets": {k: p.to_dict() for k, p in self.presets.items()},
            "stage": self._preset.to_dict(),
            "stage_generations": self._stage_generations,
            "generation": self._generation,
            "stage_start": self._stage_start,
            "counter": self._counter,
            "population": [c.to_dict() for c in self._population],
            "history": list(self._history),
            "best": self._best.to_dict() if self._best else None,
            "materials": [[m.center, m.spread, m.fraction] for m in self._materials],
            "palette": [list(c) for c in self.palette],
            "hints": [h.to_dict() for h in self.hints],
            "rng": rng_state(self._rng),
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]):
        """An explorer that continues exactly where the one that wrote ``state`` was."""
        from intuitf.tf.defaults import Material

        if state.get("format") != STATE_FORMAT:
            raise ValueError("This is not an intuitf explorer state.")
        if int(state.get("version", 0)) > STATE_VERSION:
            raise ValueError("This explorer state is newer than this intuitf understands.")
        if state.get("method") != cls.method:
            raise ValueError(f"State is for method {state.get('method')!r}, not {cls.method!r}.")
        self = cls.__new__(cls)
        self.population_size = int(state["population_size"])
        self.n_gaussians = int(state["n_gaussians"])
        self.seed = int(state["seed"])
        vr = state.get("value_range")
        self.value_range = tuple(vr) if vr else None
        self.bounds = Bounds.from_dict(state["bounds"])
        self.presets = {k: StagePreset.from_dict(v) for k, v in state["presets"].items()}
        self._preset = StagePreset.from_dict(state["stage"])
        self._stage_generations = int(state["stage_generations"])
        self._generation = int(state["generation"])
        self._stage_start = int(state["stage_start"])
        self._counter = int(state["counter"])
        self._population = [Candidate.from_dict(c) for c in state["population"]]
        self._history = [str(h) for h in state["history"]]
        self._best = Candidate.from_dict(state["best"]) if state.get("best") else None
        self._materials = [Material(*m) for m in state.get("materials", [])]
        self.palette = _palette(state.get("palette", ()))
        self.hints = as_hints(state.get("hints", ()))
        self._rng = rng_from_state(state["rng"])
        self._restore_extra(state)
        return self

    def _restore_extra(self, state: Mapping[str, Any]) -> None:
        """Hook for subclasses with more state."""
