"""CMA-ES (from the ``cma`` package) behind the Explorer's ask/tell interface.

CMA-ES searches the normalised vector encoding of a TF (:func:`~intuitf.explorer.genome.encode`)
and is told rank positions as f-values, so only the ranking matters, as with the GA.

``cma``'s strategy object holds numpy arrays and callables that do not serialise to JSON.
Rather than pickling it, :meth:`CMAExplorer.state_dict` records the constructor arguments and
every event since (rankings told, stage changes); :meth:`CMAExplorer.from_state` rebuilds the
explorer by replaying them. The strategy draws its normal samples from the explorer's own
seeded generator, so the replay is bit for bit. Replaying costs no rendering or judging.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import cma
import numpy as np

from intuitf.explorer.base import STATE_FORMAT, STATE_VERSION, BaseExplorer
from intuitf.explorer.bounds import Bounds
from intuitf.explorer.candidate import Candidate
from intuitf.explorer.genome import decode, encode
from intuitf.explorer.hints import as_hints
from intuitf.explorer.stages import StagePreset
from intuitf.tf.gaussian import GaussianTF


class CMAExplorer(BaseExplorer):
    """CMA-ES over the TF encoding; rank-based, seeded, no elites (every candidate is new).

    ``sigma0`` is the initial step size in the [0, 1] encoding for the first stage and
    ``stage_sigma`` the one a later stage restarts with (around the best TF so far, or the
    ``base`` given to :meth:`set_stage`). The start point is the first ``initial`` TF, else
    a TF placed on the histogram's materials, else a random one.
    """

    method = "cmaes"

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
        hints: Sequence = (),
        sigma0: float = 0.2,
        stage_sigma: float = 0.15,
    ) -> None:
        self.sigma0 = float(sigma0)
        self.stage_sigma = float(stage_sigma)
        self._args = {
            "population": int(population),
            "n_gaussians": int(n_gaussians),
            "generations": int(generations),
            "stage": stage.to_dict() if isinstance(stage, StagePreset) else str(stage),
            "seed": int(seed),
            "histogram": None if histogram is None else np.asarray(histogram).ravel().tolist(),
            "value_range": list(value_range) if value_range else None,
            "initial": [tf.to_dict() for tf in initial],
            "bounds": bounds.to_dict() if bounds else None,
            "presets": {k: p.to_dict() for k, p in presets.items()} if presets else None,
            "palette": [list(c) for c in palette],
            "hints": [h.to_dict() for h in as_hints(hints)],
            "sigma0": self.sigma0,
            "stage_sigma": self.stage_sigma,
        }
        self._events: list[list] = []
        self._initial = list(initial)
        super().__init__(
            population=population,
            n_gaussians=n_gaussians,
            generations=generations,
            stage=stage,
            seed=seed,
            histogram=histogram,
            value_range=value_range,
            initial=initial,
            bounds=bounds,
            presets=presets,
            palette=palette,
            hints=hints,
        )

    # -- the strategy ----------------------------------------------------------------------
    def _start(self, template: GaussianTF, sigma: float) -> list[Candidate]:
        self._template = template
        x0 = encode(template, self.bounds)
        if x0.size == 0:
            raise ValueError("CMA-ES needs at least one free Gaussian.")
        rng = self._rng
        opts = {
            "popsize": self.population_size,
            "bounds": [0.0, 1.0],
            "seed": np.nan,  # cma must not touch numpy's global generator
            "randn": lambda *shape: rng.standard_normal(shape),
            "verbose": -9,
            "verb_log": 0,
            "verb_disp": 0,
            "tolfun": 0.0,
            "tolx": 0.0,
            "tolflatfitness": 10**9,
        }
        self._es = cma.CMAEvolutionStrategy(x0, sigma, opts)
        return self._sample()

    def _sample(self) -> list[Candidate]:
        self._X = self._es.ask()
        return [self._new(decode(x, self._template, self.bounds), "cma") for x in self._X]

    def _fresh_population(
        self, initial: Sequence[GaussianTF], size: int | None = None, keep: Sequence[Candidate] = ()
    ) -> list[Candidate]:
        # The first population: CMA-ES samples around the start point.
        if initial:
            template = initial[0]
        elif any(h.center is not None for h in self.hints):
            template = self._hinted()
        elif self._materials:
            template = self._seeded()
        else:
            template = self._random()
        return self._start(template, self.sigma0)

    def _next_population(
        self, ranked: list[Candidate], fitness: np.ndarray, progress: float
    ) -> list[Candidate]:
        pos = {c.id: k for k, c in enumerate(ranked)}
        # f-values are rank positions (lower is better): CMA-ES only uses their order.
        f = [float(pos[c.id]) for c in self._asked]
        self._es.tell(self._X, f)
        return self._sample()

    def tell(self, ranking: Sequence[str], fitness: Sequence[float] | None = None) -> None:
        """Report the ranking (ids, best first); ``fitness`` is ignored (only ranks count)."""
        self._asked = list(self._population)
        super().tell(ranking, None)
        self._events.append(["tell", [str(i) for i in ranking]])

    def set_stage(
        self,
        stage: str | StagePreset,
        *,
        generations: int | None = None,
        selected: Sequence[int] = (),
        base: GaussianTF | None = None,
        joining: Sequence[GaussianTF] = (),
    ) -> None:
        """Restart CMA-ES for another stage around ``base`` (default: the best TF so far).

        A freezing stage encodes only the ``selected`` Gaussians; the rest stay fixed.
        ``joining`` TFs are not taken: a CMA-ES population is drawn from one distribution
        around its start, and a TF of another size cannot join it as it is.
        """
        preset = self._resolve(stage)
        if generations is not None and int(generations) < 1:
            raise ValueError("generations must be at least 1.")
        start = base or (self._best.tf if self._best else self._population[0].tf)
        if preset.freeze_unselected:
            sel = sorted({int(i) for i in selected})
            if not sel or sel[0] < 0 or sel[-1] >= len(start):
                raise ValueError(f"Selected Gaussian indices {sel} are empty or out of range.")
            template = start.freeze(sel)
        else:
            template = start.unfreeze()
        if generations is not None:
            self._stage_generations = int(generations)
        self.bounds = self.bounds.covering([template])
        self._preset = preset
        self._stage_start = self._generation
        self._population = self._start(template, self.stage_sigma)
        self._events.append(
            [
                "stage",
                {
                    "stage": stage.to_dict() if isinstance(stage, StagePreset) else str(stage),
                    "generations": generations,
                    "selected": [int(i) for i in selected],
                    "base": base.to_dict() if base is not None else None,
                },
            ]
        )

    # -- state by replay -------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Constructor arguments plus every ranking and stage change since (JSON-able)."""
        return {
            "format": STATE_FORMAT,
            "version": STATE_VERSION,
            "method": self.method,
            "args": self._args,
            "events": [list(e) for e in self._events],
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> CMAExplorer:
        """Rebuild the explorer by replaying its rankings and stage changes."""
        if state.get("format") != STATE_FORMAT or state.get("method") != cls.method:
            raise ValueError("This is not an intuitf CMA-ES explorer state.")

        def stage_of(v: Any) -> Any:
            return StagePreset.from_dict(v) if isinstance(v, dict) else v

        a = state["args"]
        ex = cls(
            population=a["population"],
            n_gaussians=a["n_gaussians"],
            generations=a["generations"],
            stage=stage_of(a["stage"]),
            seed=a["seed"],
            histogram=None if a["histogram"] is None else np.asarray(a["histogram"]),
            value_range=tuple(a["value_range"]) if a["value_range"] else None,
            initial=[GaussianTF.from_dict(d) for d in a["initial"]],
            bounds=Bounds.from_dict(a["bounds"]) if a["bounds"] else None,
            presets={k: StagePreset.from_dict(v) for k, v in a["presets"].items()}
            if a["presets"]
            else None,
            palette=a.get("palette", ()),
            hints=a.get("hints", ()),
            sigma0=a["sigma0"],
            stage_sigma=a["stage_sigma"],
        )
        for kind, payload in state["events"]:
            if kind == "tell":
                ex.tell(payload)
            elif kind == "stage":
                ex.set_stage(
                    stage_of(payload["stage"]),
                    generations=payload["generations"],
                    selected=payload["selected"],
                    base=GaussianTF.from_dict(payload["base"]) if payload["base"] else None,
                )
            else:
                raise ValueError(f"Unknown event {kind!r} in a CMA-ES explorer state.")
        return ex
