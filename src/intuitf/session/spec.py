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

from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from intuitf.errors import SessionError

#: Bumped when a spec written by an older intuitf needs converting to be read.
SPEC_VERSION = 1


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


class VolumeSpec(_Model):
    """Where the volume comes from: a path (file or folder) with reader options, or ``phantom``."""

    source: str
    shape: tuple[int, int, int] | None = None
    dtype: str | None = None
    byte_order: Literal["little", "big"] | None = None
    spacing: tuple[float, float, float] | None = None
    max_dim: int | None = Field(default=None, ge=2)

    def reader_options(self) -> dict[str, Any]:
        """Keyword arguments for :func:`intuitf.volume.load_volume`."""
        kw = self.model_dump(exclude={"source"})
        return {k: v for k, v in kw.items() if v is not None}

    def load(self):
        """Read the volume (raises :class:`~intuitf.errors.VolumeError` with a hint)."""
        from intuitf.volume import load_volume

        return load_volume(self.source, **self.reader_options())


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

        unknown = sorted(set(v) - RunSettings.field_names())
        if unknown:
            raise ValueError(f"unknown settings {unknown}")
        try:
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


def parse_spec(data: Any) -> RunSpec:
    """A :class:`RunSpec` from plain data, or :class:`SessionError` naming every problem."""
    if isinstance(data, RunSpec):
        return data
    try:
        return RunSpec.model_validate(data)
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in err['loc']) or 'spec'}: {err['msg']}"
            for err in exc.errors()
        )
        raise SessionError(
            f"The run spec is not valid: {problems}.",
            "Fix the fields named above (see intuitf.session.spec.RunSpec).",
        ) from None
