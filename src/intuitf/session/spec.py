"""RunSpec: everything a run is, as plain data that scripts, the CLI and the web app can write.

A spec is serialisable and versioned; :meth:`Session.open` builds the volume, the judge, the
verdict store and the budget from it, and writes it into the run folder's ``run.json`` so that
:meth:`Session.resume` needs nothing but the folder. Plain data makes a valid spec::

    RunSpec(
        volume="phantom",
        intent={"kind": "text", "text": "opaque ivory bone"},
        judge="metric",
        settings={"population": 6, "generations": 2, "image_size": 48},
    )

Pictures of an intent (reference, sketch, base) are paths here; :meth:`Session.open` copies
them into the run folder (``intent/``) and the spec written there points at the copies.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictBool,
    ValidationError,
    field_validator,
    model_validator,
)

from intuitf.errors import SessionError
from intuitf.explorer.methods import METHODS

#: Bumped when a spec written by an older intuitf needs converting to be read.
SPEC_VERSION = 1

#: The stages a run's plan may name.
STAGES = ("initialize", "customize", "refine")


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class SpecProblems(ValueError):
    """Several bad fields at once: (dotted field path, what is wrong) pairs.

    Raised inside a validator, it reaches :func:`parse_spec` through pydantic's error context,
    which reports every pair (a validator's plain ValueError would name only the field).
    """

    def __init__(self, problems: list[tuple[str, str]]) -> None:
        super().__init__("; ".join(f"{path}: {msg}" for path, msg in problems))
        self.problems = problems


_Unit = Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]
_Positive = Annotated[int, Field(ge=1)]


class SettingsSchema(BaseModel):
    """The type, range or choices of every :class:`RunSettings` field, checked before a run
    folder is written. Only the fields a spec gives are checked; the rest keep their defaults.
    """

    model_config = ConfigDict(extra="forbid")

    population: int = Field(32, ge=4, le=1000)
    generations: int = Field(12, ge=1, le=10_000)
    n_gaussians: int = Field(5, ge=1, le=16)
    seed: int = Field(0, ge=0, le=2**63 - 1)
    explorer: Literal[METHODS] = "ga"  # type: ignore[valid-type]
    protocol: Literal["efficient", "paper"] = "efficient"
    image_size: int = Field(256, ge=32, le=2048)
    output_size: int = Field(512, ge=32, le=4096)
    shading: StrictBool = True
    background: tuple[_Unit, _Unit, _Unit] = (0.0, 0.0, 0.0)
    camera: dict[str, Any] = Field(default_factory=dict)
    top_k: int = Field(4, ge=1, le=1000)
    init_share: float = Field(0.34, ge=0.0, le=1.0, allow_inf_nan=False)
    stages: list[tuple[Literal[STAGES], _Positive]] = Field(default_factory=list)  # type: ignore[valid-type]
    palette_hint: StrictBool = True
    device: Literal["auto", "cpu", "cuda"] = "auto"
    material_hints: StrictBool = True
    name_structures: StrictBool = False
    fit_sketch: StrictBool = True

    @field_validator("camera")
    @classmethod
    def _camera_valid(cls, v: dict[str, Any]) -> dict[str, Any]:
        if v:
            from intuitf.errors import RenderError
            from intuitf.render.camera import Camera

            try:
                Camera.from_dict(v)
            except RenderError as exc:
                raise ValueError(exc.message) from None
        return v


def check_settings(settings: dict[str, Any]) -> dict[str, Any]:
    """``settings`` checked field by field: the given fields, their values normalised (``"8"``
    becomes 8); :class:`SpecProblems` naming every bad field (``settings.population``)."""
    from intuitf.session.settings import RunSettings

    problems: list[tuple[str, str]] = []
    known = RunSettings.field_names()
    for name in sorted(set(settings) - known):
        problems.append(
            (f"settings.{name}", f"unknown setting (known: {', '.join(sorted(known))})")
        )
    checked = {k: v for k, v in settings.items() if k in SettingsSchema.model_fields}
    try:
        model = SettingsSchema.model_validate(checked)
    except ValidationError as exc:
        for err in exc.errors():
            path = ".".join(str(p) for p in err["loc"])
            problems.append((f"settings.{path}", _plain(err["msg"])))
        model = None
    if problems:
        raise SpecProblems(problems)
    out = dict(settings)
    dumped = model.model_dump(mode="json") if model is not None else {}
    for k in checked:
        out[k] = dumped[k]
    return out


def _plain(msg: str) -> str:
    """pydantic's message without its "Value error, " prefix."""
    return msg.removeprefix("Value error, ")


#: Judge options whose values are checked here (others are checked by the judge itself).
_JUDGE_OPTION_TYPES: dict[str, Any] = {
    "swap": Literal["always", "never", "auto"],
    "compose": Literal["parts", "side_by_side"],
    "image_format": Literal["png", "jpeg"],
    "jpeg_quality": Annotated[int, Field(ge=1, le=100)],
    "max_concurrency": Annotated[int, Field(ge=1)],
    "timeout": Annotated[float, Field(gt=0, allow_inf_nan=False)],
    "deadline": Annotated[float, Field(gt=0, allow_inf_nan=False)],
    "max_retries": Annotated[int, Field(ge=0)],
    "answer_retries": Annotated[int, Field(ge=0)],
    "temperature": Annotated[float, Field(ge=0, allow_inf_nan=False)],
    "structured": StrictBool,
    "max_tokens": Annotated[int, Field(ge=1)],
    "backoff_base": Annotated[float, Field(ge=0, allow_inf_nan=False)],
    "backoff_max": Annotated[float, Field(ge=0, allow_inf_nan=False)],
    "model": str,
    "name": str,
    "api_key": str,
    "provider": str,
}


def _judge_option_names() -> set[str]:
    """What a model judge's constructor takes (as the factory passes ``options`` on)."""
    import inspect

    from intuitf.evaluator.mllm import MLLMJudge

    params = inspect.signature(MLLMJudge.__init__).parameters
    named = {n for n, p in params.items() if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}
    # Made by the session from the spec itself, never passed as options.
    return (named - {"self", "cache", "budget", "prices", "base_url"}) | {"model"}


def check_judge_options(options: dict[str, Any]) -> dict[str, Any]:
    """Judge ``options`` checked: known names, and the values of those listed above."""
    from pydantic import TypeAdapter

    if not options:
        return options
    problems: list[tuple[str, str]] = []
    known = _judge_option_names()
    out = dict(options)
    for name, value in options.items():
        path = f"judge.options.{name}"
        if name not in known:
            problems.append((path, f"unknown judge option (known: {', '.join(sorted(known))})"))
            continue
        kind = _JUDGE_OPTION_TYPES.get(name)
        if kind is None:
            continue
        try:
            out[name] = TypeAdapter(kind).validate_python(value)
        except ValidationError as exc:
            problems += [(path, _plain(e["msg"])) for e in exc.errors()]
    if problems:
        raise SpecProblems(problems)
    return out


class VolumeSpec(_Model):
    """Where the volume comes from: a path (file or folder) with reader options, or ``phantom``.

    A path is stored absolute (made so from the working directory when the spec is read), so
    a run continues from any working directory. ``relative`` is the same file as seen from the
    run folder, kept when the volume sits near it (:meth:`anchored`): a tree moved or mounted
    elsewhere as a whole still finds its volume (:meth:`load` says which it used).
    """

    source: str
    shape: tuple[int, int, int] | None = None
    dtype: str | None = None
    byte_order: Literal["little", "big"] | None = None
    spacing: tuple[float, float, float] | None = None
    max_dim: int | None = Field(default=None, ge=2)
    relative: str | None = None

    @field_validator("source")
    @classmethod
    def _absolute(cls, v: str) -> str:
        if _is_builtin(v):
            return v
        return str(Path(v).expanduser().absolute())

    def reader_options(self) -> dict[str, Any]:
        """Keyword arguments for :func:`intuitf.volume.load_volume`."""
        kw = self.model_dump(exclude={"source", "relative"})
        return {k: v for k, v in kw.items() if v is not None}

    def anchored(self, run_dir: str | Path) -> VolumeSpec:
        """This spec with ``relative`` set for a run in ``run_dir``: when the volume sits in the
        tree of the run folder's near ancestors (at most ``_NEAR`` levels up), as in
        ``project/scans/head.nii`` beside ``project/runs/r1``."""
        if _is_builtin(self.source):
            return self
        run = Path(run_dir).expanduser().absolute()
        try:
            rel = os.path.relpath(self.source, run)
        except ValueError:  # another drive (Windows)
            rel = None
        if rel is not None and Path(rel).parts.count("..") > _NEAR:
            rel = None
        return self.model_copy(update={"relative": rel})

    def load(self, run_dir: str | Path | None = None):
        """Read the volume (raises :class:`~intuitf.errors.VolumeError` with a hint).

        When the absolute path is gone but the volume is found at ``relative`` from
        ``run_dir`` (the tree was moved), that one is read, and the volume's notes say so.
        """
        from intuitf.volume import load_volume

        source, note = self.source, None
        if run_dir is not None and self.relative and not Path(source).exists():
            moved = Path(run_dir).expanduser().absolute() / self.relative
            if moved.exists():
                source = str(moved.resolve())
                note = (
                    f"Volume read from {source} (where it sits relative to the run folder); "
                    f"the recorded path {self.source} is gone."
                )
        vol = load_volume(source, **self.reader_options())
        if note is not None and isinstance(getattr(vol, "notes", None), list):
            vol.notes.append(note)
        return vol


#: How many levels above a run folder its volume may sit and still be found from it.
_NEAR = 3


def _is_builtin(source: str) -> bool:
    """A source that names no file: the phantom, or nothing (an in-memory volume)."""
    return (
        not source
        or source.startswith("builtin:")
        or (source == "phantom" and not Path(source).exists())
    )


class IntentSpec(_Model):
    """What the person wants: text, a reference picture, a sketch over a base picture, an edit.

    ``selected`` are the Gaussians (0-based indices into the TF being refined) an ``edit``
    changes. Picture fields are paths.
    """

    kind: Literal["none", "text", "image", "sketch", "edit"] = "none"
    text: str | None = None
    about: str | None = None
    reference: str | None = None
    sketch: str | None = None
    base: str | None = None
    selected: list[int] = Field(default_factory=list)

    @model_validator(mode="after")
    def _complete(self) -> IntentSpec:
        need = {"text": ["text"], "image": ["reference"], "sketch": ["sketch", "base"]}
        missing = [f for f in need.get(self.kind, []) if not getattr(self, f)]
        if self.kind == "edit" and (not self.text or not self.selected):
            missing += [f for f in ("text", "selected") if not getattr(self, f)]
        if missing:
            raise ValueError(f"a {self.kind!r} intent needs {', '.join(missing)}")
        if any(i < 0 for i in self.selected):
            raise ValueError("selected Gaussian indices are 0-based and not negative")
        return self


class JudgeSpec(_Model):
    """Which judge and what it may spend: ``metric``, ``openai:MODEL``, ..., or a server URL."""

    spec: str = "metric"
    base_url: str | None = None
    budget_usd: float | None = Field(default=None, ge=0)
    budget_calls: int | None = Field(default=None, ge=0)
    options: dict[str, Any] = Field(default_factory=dict)

    @field_validator("options")
    @classmethod
    def _options_valid(cls, v: dict[str, Any]) -> dict[str, Any]:
        return check_judge_options(v)

    @property
    def is_model(self) -> bool:
        return self.spec != "metric"


class ParentLink(_Model):
    """Where a branch comes from: a run, and in it a generation and/or a candidate."""

    run: str
    generation: int | None = Field(default=None, ge=0)
    candidate: str | None = None
    selected: list[int] = Field(default_factory=list)


class RunSpec(_Model):
    """A run as data. See the module notes; ``settings`` are :class:`RunSettings` fields."""

    version: int = SPEC_VERSION
    name: str | None = None
    volume: VolumeSpec
    intent: IntentSpec = Field(default_factory=IntentSpec)
    judge: JudgeSpec = Field(default_factory=JudgeSpec)
    settings: dict[str, Any] = Field(default_factory=dict)
    #: Transfer functions (their JSON form) that join the first population.
    initial: list[dict[str, Any]] = Field(default_factory=list)
    parent: ParentLink | None = None

    @field_validator("volume", mode="before")
    @classmethod
    def _volume_from_text(cls, v: Any) -> Any:
        return {"source": str(v)} if isinstance(v, str | Path) else v

    @field_validator("intent", mode="before")
    @classmethod
    def _intent_from_text(cls, v: Any) -> Any:
        if v is None:
            return {}
        return {"kind": "text", "text": v} if isinstance(v, str) else v

    @field_validator("judge", mode="before")
    @classmethod
    def _judge_from_text(cls, v: Any) -> Any:
        return {"spec": v} if isinstance(v, str) else v

    @field_validator("settings", mode="after")
    @classmethod
    def _settings_valid(cls, v: dict[str, Any]) -> dict[str, Any]:
        from intuitf.session.settings import RunSettings

        v = check_settings(v)
        try:  # what the schema cannot say alone (RunSettings.validate has the last word)
            RunSettings.from_dict(v).validate()
        except SessionError as exc:
            raise ValueError(exc.message) from exc
        return v

    @field_validator("version")
    @classmethod
    def _known_version(cls, v: int) -> int:
        if v > SPEC_VERSION:
            raise ValueError(
                f"this spec was written by a newer intuitf (version {v}); upgrade intuitf"
            )
        return v

    # -- conversions ----------------------------------------------------------------------
    def run_settings(self):
        """The validated :class:`RunSettings` of this spec."""
        from intuitf.session.settings import RunSettings

        s = RunSettings.from_dict(self.settings)
        if self.intent.kind == "edit" and not s.stages:
            s.stages = [("refine", s.generations)]
        s.validate()
        return s

    def to_dict(self) -> dict[str, Any]:
        return self.model_dump(mode="json")

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunSpec:
        """Validate plain data; a bad spec raises :class:`SessionError` saying what is wrong."""
        return parse_spec(data)


class SpecError(SessionError):
    """A run spec that is not valid; ``fields`` maps each bad field's dotted path (in the
    words of the API: ``settings.population``, ``judge.options.timeout``) to what is wrong,
    so a front end can name its own words for them (a flag, a form field)."""

    def __init__(self, fields: dict[str, str], hint: str | None = None) -> None:
        problems = "; ".join(f"{path}: {msg}" for path, msg in fields.items())
        super().__init__(
            f"The run spec is not valid: {problems}.",
            hint or "Fix the fields named above (see intuitf.session.spec.RunSpec).",
        )
        self.fields = fields


def spec_problems(exc: ValidationError) -> dict[str, str]:
    """Every bad field of a failed RunSpec validation, by dotted path, in plain words."""
    fields: dict[str, str] = {}
    for err in exc.errors():
        inner = (err.get("ctx") or {}).get("error")
        base = ".".join(str(p) for p in err["loc"])
        if isinstance(inner, SpecProblems):
            for path, msg in inner.problems:
                fields.setdefault(path, msg)
            continue
        fields.setdefault(base or "spec", _plain(err["msg"]))
    return fields


def parse_spec(data: Any) -> RunSpec:
    """A :class:`RunSpec` from plain data, or :class:`SpecError` naming every bad field."""
    if isinstance(data, RunSpec):
        return data
    try:
        return RunSpec.model_validate(data)
    except ValidationError as exc:
        raise SpecError(spec_problems(exc)) from None
