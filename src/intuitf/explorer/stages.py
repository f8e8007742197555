"""Stage presets: how the Explorer searches in initialization, customization and refinement.

Each preset gives rates and step sizes as :class:`Decay` schedules over the stage's
progress (0 at its first generation, 1 at its last), the elite share, the selection
pressure, and the aspect set the evaluator should judge with.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

from intuitf.explorer.fitness import PressureSchedule
from intuitf.explorer.operators import PAPER_GROUPS, MutationParams

ASPECT_SETS = ("quality", "intent", "edit")


@dataclass(frozen=True)
class Decay:
    """``max(start · (1 − progress), floor)``: a linear decay that stops at a floor.

    The authors' schedule; it restarts with each stage.
    """

    start: float
    floor: float

    def at(self, progress: float) -> float:
        t = min(1.0, max(0.0, float(progress)))
        return max(self.start * (1.0 - t), self.floor)


def _const(v: float) -> Decay:
    return Decay(v, v)


@dataclass(frozen=True)
class StagePreset:
    """Everything that distinguishes one stage's search from another's.

    ``aspects`` names the aspect set the session should ask the evaluator to judge with.
    ``freeze_unselected`` makes :meth:`Explorer.set_stage` freeze every Gaussian but the
    selected ones. ``elite_shares`` is a list of (progress limit, share): the first entry
    whose limit exceeds the progress applies. ``seed_share`` is the part of a fresh
    population placed on the histogram's materials. ``init_sampling`` is "log" (heights and
    widths log-uniform within :attr:`Bounds.height_init` / :attr:`Bounds.width`) or
    "uniform" (uniform within the hard bounds, as the authors did). When the explorer has a
    palette (colours the intent asks for), ``palette_share`` of new colours are drawn from it
    and a mutation recolours a Gaussian from it with ``recolor_prob``; with ``palette_only``
    a colour changes only that way (no HSL steps). ``local_share`` of the
    places that are not elites go to mutated copies of the top of the ranking (see
    :class:`~intuitf.explorer.ga.GeneticExplorer`); the rest are bred by roulette selection,
    crossover and mutation. With material hints (what the words say about single materials:
    :mod:`intuitf.explorer.hints`), ``hint_share`` of a fresh population is placed on them
    and a mutation makes a Gaussian follow its material's hint with ``hint_prob``; when the
    stage begins, ``stage_hint_share`` of the population kept from the stage before is
    replaced by fresh hinted TFs (see :meth:`Explorer.set_stage`). When every hint that
    shows a material comes from a sketch's strokes, ``stroke_hint_share`` is used in place
    of ``hint_share``: a stroke says which values take its colour, while a histogram seed
    spreads the strokes' colours over the materials at random (the tooth's blue root colour
    on its crown's dentin), which the first generation, judged on quality alone, cannot tell
    from what was drawn.
    ``pair_by_mean``: crossover pairs each
    Gaussian with the other parent's nearest one (else k-th lowest with k-th lowest).
    """

    name: str
    aspects: str
    mutation_rate: Decay = Decay(0.4, 0.1)
    mean_rate_factor: float = 1.0
    mean_step: Decay = Decay(0.04, 0.01)
    width_step: Decay = Decay(0.4, 0.1)
    height_step: Decay = Decay(0.8, 0.2)
    color_rate: Decay = Decay(0.4, 0.15)
    hue_step: Decay = Decay(0.08, 0.02)
    sl_step: Decay = Decay(0.2, 0.05)
    swap_prob: float = 0.2
    channel_prob: float = 0.05
    toggle_prob: float = 0.0
    additive_steps: bool = False
    crossover_rate: Decay = Decay(0.9, 0.6)
    attr_prob: float = 0.4
    groups: tuple[tuple[str, ...], ...] = PAPER_GROUPS
    fallback_prob: float = 0.5
    elite_shares: tuple[tuple[float, float], ...] = ((0.4, 0.05), (0.7, 0.10), (1.01, 0.15))
    pressure: PressureSchedule = field(default_factory=PressureSchedule)
    dedup: bool = True
    seed_share: float = 2.0 / 3.0
    init_sampling: str = "log"
    freeze_unselected: bool = False
    palette_share: float = 0.8
    recolor_prob: float = 0.1
    palette_only: bool = False
    local_share: Decay = _const(0.25)
    pair_by_mean: bool = True
    hint_share: float = 0.5
    stroke_hint_share: float = 1.0
    hint_prob: float = 0.1
    stage_hint_share: float = 0.0

    def __post_init__(self) -> None:
        if self.aspects not in ASPECT_SETS:
            raise ValueError(f"aspects must be one of {ASPECT_SETS}, got {self.aspects!r}.")
        if self.init_sampling not in ("log", "uniform"):
            raise ValueError(
                f"init_sampling must be 'log' or 'uniform', got {self.init_sampling!r}."
            )

    def mutation_params(
        self, progress: float, palette: tuple = (), hints: tuple = ()
    ) -> MutationParams:
        """Rates and steps at ``progress`` (0..1) through the stage (``palette`` and
        ``hints``: see above)."""
        rate = self.mutation_rate.at(progress)
        return MutationParams(
            rate=rate,
            mean_rate=min(1.0, rate * self.mean_rate_factor),
            mean_step=self.mean_step.at(progress),
            width_step=self.width_step.at(progress),
            height_step=self.height_step.at(progress),
            color_rate=self.color_rate.at(progress),
            hue_step=self.hue_step.at(progress),
            sl_step=self.sl_step.at(progress),
            swap_prob=self.swap_prob,
            channel_prob=self.channel_prob,
            toggle_prob=self.toggle_prob,
            additive=self.additive_steps,
            palette=tuple(palette),
            recolor_prob=self.recolor_prob,
            palette_only=self.palette_only,
            hints=tuple(hints),
            hint_prob=self.hint_prob,
        )

    def elite_share(self, progress: float) -> float:
        for limit, share in self.elite_shares:
            if progress < limit:
                return share
        return self.elite_shares[-1][1]

    # -- serialisation ---------------------------------------------------------------------
    def to_dict(self) -> dict:
        d: dict = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, Decay):
                v = [v.start, v.floor]
            elif isinstance(v, PressureSchedule):
                v = [v.min_pressure, v.max_pressure, v.k]
            elif isinstance(v, tuple):
                v = [list(x) for x in v]
            d[f.name] = v
        return d

    @classmethod
    def from_dict(cls, d: dict) -> StagePreset:
        kw: dict = {}
        for f in fields(cls):
            if f.name not in d:
                continue
            v = d[f.name]
            default = getattr(STAGES["initialize"], f.name)
            if isinstance(default, Decay):
                v = Decay(float(v[0]), float(v[1]))
            elif isinstance(default, PressureSchedule):
                v = PressureSchedule(*(float(x) for x in v))
            elif f.name == "groups":
                v = tuple(tuple(str(k) for k in g) for g in v)
            elif f.name == "elite_shares":
                v = tuple((float(a), float(b)) for a, b in v)
            kw[f.name] = v
        return cls(**kw)


#: Initialization: quality aspects only, broad search with high rates that decay; two thirds
#: of the first population on the histogram's materials. When the intent names colours (a
#: palette), every colour is one of them, new or mutated: judged on quality alone, a
#: teal-and-red chest outranked the ivory-and-red ones asked for (colour separation), and a
#: pink tree (a channel permutation of the gold asked for) led the bonsai's generation 1, so
#: the first results showed colours nobody asked for. Customization tries other colours again.
INITIALIZE = StagePreset(
    name="initialize", aspects="quality", toggle_prob=0.06, palette_share=1.0, palette_only=True
)

#: Customization: intent aspects; rates raised again from where initialization left them
#: (the schedule restarts), but positions barely move so the structures found are kept, and
#: half the places go to mutated copies of the best. Colours are not reset; palette colours
#: are tried more often. A quarter of the population it starts from is replaced by fresh
#: TFs on the words' materials: initialization judged quality alone and may have dropped
#: every TF in the asked colours before anything judged the words. (Rates, crossover and
#: local share tuned on the recovery benchmark's engine task:
#: benchmarks/recovery_ablation.py.)
CUSTOMIZE = StagePreset(
    name="customize",
    aspects="intent",
    mutation_rate=Decay(0.2, 0.08),
    mean_rate_factor=0.25,
    mean_step=Decay(0.01, 0.003),
    width_step=Decay(0.3, 0.08),
    height_step=Decay(0.7, 0.15),
    color_rate=Decay(0.2, 0.08),
    hue_step=Decay(0.1, 0.02),
    sl_step=Decay(0.25, 0.05),
    swap_prob=0.25,
    toggle_prob=0.04,
    crossover_rate=Decay(0.6, 0.4),
    recolor_prob=0.15,
    local_share=_const(0.5),
    hint_prob=0.15,
    stage_hint_share=0.25,
)

#: Refinement: only the selected Gaussians evolve (the rest are frozen); edit aspects.
REFINE = StagePreset(
    name="refine",
    aspects="edit",
    mutation_rate=Decay(0.6, 0.2),
    mean_rate_factor=0.5,
    mean_step=Decay(0.02, 0.005),
    width_step=Decay(0.35, 0.08),
    height_step=Decay(0.8, 0.15),
    color_rate=Decay(0.6, 0.2),
    hue_step=Decay(0.1, 0.02),
    sl_step=Decay(0.25, 0.05),
    swap_prob=0.1,
    crossover_rate=Decay(0.7, 0.5),
    seed_share=0.0,
    freeze_unselected=True,
    local_share=_const(0.4),
    hint_prob=0.3,
)

STAGES: dict[str, StagePreset] = {p.name: p for p in (INITIALIZE, CUSTOMIZE, REFINE)}


def paper_settings() -> dict[str, StagePreset]:
    """The authors' GA settings, stage by stage, in normalised units (for comparisons).

    Their defaults: per-parameter rate 0.4→0.1; additive steps of 0.4→0.05 (height),
    0.2→0.05 (width) and 0.04→0.01 (mean) of each bound's span; colour rate 0.4→0.2 with
    hue step 0.15→0.1 radians (0.024→0.016 of a turn, what their code effectively did) and
    saturation/lightness 0.2→0.05; colour swap 0.3; crossover always, each of mean, width,
    height and colour exchanged with 0.6; elite share 5/10/15 %; uniform initial sampling,
    no histogram seeds, no palette and no duplicate removal. Intent stage: mean rate and
    step × 0.1.
    Elites pass unchanged here (their code lost them, a bug not kept).
    """
    two_pi = 6.283185307179586
    base = StagePreset(
        name="paper-initialize",
        aspects="quality",
        mutation_rate=Decay(0.4, 0.1),
        mean_rate_factor=1.0,
        mean_step=Decay(0.04, 0.01),
        width_step=Decay(0.2, 0.05),
        height_step=Decay(0.4, 0.05),
        color_rate=Decay(0.4, 0.2),
        hue_step=Decay(0.15 / two_pi, 0.1 / two_pi),
        sl_step=Decay(0.2, 0.05),
        swap_prob=0.3,
        channel_prob=0.0,
        additive_steps=True,
        crossover_rate=_const(1.0),
        attr_prob=0.6,
        groups=(("mean",), ("width",), ("height",), ("color",)),
        fallback_prob=0.5,
        dedup=False,
        seed_share=0.0,
        init_sampling="uniform",
        palette_share=0.0,
        recolor_prob=0.0,
        local_share=_const(0.0),
        pair_by_mean=False,
        hint_share=0.0,
        stroke_hint_share=0.0,
        hint_prob=0.0,
    )
    customize = replace(
        base,
        name="paper-customize",
        aspects="intent",
        mean_rate_factor=0.1,
        mean_step=Decay(0.004, 0.001),
    )
    refine = replace(base, name="paper-refine", aspects="edit", freeze_unselected=True)
    return {"initialize": base, "customize": customize, "refine": refine}
