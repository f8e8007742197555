"""Settings of an optimisation run, kept in run.json so a resumed run uses exactly the same."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

from intuitf.errors import SessionError


@dataclass
class RunSettings:
    """Everything that decides what a run does, apart from the volume, intent and judge.

    ``stages`` is the plan: a list of (stage name, generations). By default a run with an
    intent spends about a third of its generations in ``initialize`` (quality only, to find
    the volume's structures) and the rest in ``customize`` (the intent); a run without an
    intent stays in ``initialize``, and a sketch fitted to its strokes (``fit_sketch``) goes
    straight to ``customize``.

    ``palette_hint``: draw part of the new colours from those the intent asks for (the
    reference picture's dominant colours, the sketch's strokes, the colour words of the text).

    ``material_hints``: seed part of the first population, and draw colour and height
    mutations, from the materials the text names ("opaque ivory bone, faint red skin"),
    placed on the volume's histogram (:mod:`intuitf.intent.hints`).
    """

    population: int = 32
    generations: int = 12
    n_gaussians: int = 5
    seed: int = 0
    explorer: str = "ga"
    protocol: str = "efficient"
    image_size: int = 256
    output_size: int = 512
    shading: bool = True
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    camera: dict = field(default_factory=dict)
    top_k: int = 4
    init_share: float = 0.34
    stages: list[tuple[str, int]] = field(default_factory=list)
    palette_hint: bool = True
    #: Where rendering runs: ``auto`` (an NVIDIA GPU when usable, else the CPU), cpu, cuda.
    device: str = "auto"
    material_hints: bool = True
    #: A model judge names the volume's structures from an atlas first (one request per
    #: volume, cached, paid from the run's budget); off (the default), words are matched to
    #: structures by their descriptors only. Opt-in while the names' gain over descriptors
    #: is unmeasured with a real model: every run would pay one more request for it.
    name_structures: bool = False
    #: A sketch's first generation holds a TF fitted to its strokes
    #: (:mod:`intuitf.intent.sketch_fit`, a few seconds of rendering), and the run goes
    #: straight to the strokes (``customize``): the sketch is drawn over a picture the person
    #: already has, and a quality-only first stage ranked the fitted TF by quality alone and
    #: lost it. Needs ``material_hints`` and a camera (the base picture's).
    fit_sketch: bool = True

    def validate(self) -> None:
        if not 4 <= self.population <= 1000:
            raise SessionError(f"--population must be within 4..1000, got {self.population}.")
        if not 1 <= self.generations <= 10_000:
            raise SessionError(f"--generations must be at least 1, got {self.generations}.")
        if not 1 <= self.n_gaussians <= 16:
            raise SessionError(f"--gaussians must be within 1..16, got {self.n_gaussians}.")
        if not 32 <= self.image_size <= 2048 or not 32 <= self.output_size <= 4096:
            raise SessionError(
                "Image sizes must be within 32..2048 (judging) and 32..4096 (output)."
            )
        if self.top_k < 1:
            raise SessionError("--top must be at least 1.")
        if self.device not in ("auto", "cpu", "cuda"):
            raise SessionError(f"--device must be auto, cpu or cuda, got {self.device!r}.")

    def stage_plan(self, has_intent: bool, at_intent: bool = False) -> list[tuple[str, int]]:
        """The (stage, generations) list this run follows; ``at_intent``: the run starts at
        the intent (a sketch fitted in its first generation), with no quality-only stage."""
        if self.stages:
            return [(str(s), int(n)) for s, n in self.stages]
        if has_intent and at_intent:
            return [("customize", self.generations)]
        if not has_intent or self.generations < 2:
            return [("initialize", self.generations)]
        n_init = max(1, round(self.generations * self.init_share))
        n_init = min(n_init, self.generations - 1)
        return [("initialize", n_init), ("customize", self.generations - n_init)]

    def to_dict(self) -> dict:
        d = asdict(self)
        d["background"] = list(self.background)
        d["stages"] = [list(s) for s in self.stages]
        return d

    @classmethod
    def field_names(cls) -> set[str]:
        """The names a settings dict may use."""
        return {f.name for f in fields(cls)}

    @classmethod
    def from_dict(cls, d: dict) -> RunSettings:
        known = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in known}
        if "background" in kw:
            kw["background"] = tuple(kw["background"])
        if "stages" in kw:
            kw["stages"] = [tuple(s) for s in kw["stages"]]
        return cls(**kw)
