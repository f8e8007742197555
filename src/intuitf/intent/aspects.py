"""Aspects as data: the built-in catalogue (``aspects.json``) and user catalogues that extend it.

A catalogue has two parts:

- ``aspects``: ``{key: {"name": ..., "description": ..., "weight": 1.0}}``;
- ``sets``: ``{set_key: [aspect_key | {"key": aspect_key, "weight": w}, ...]}``, the aspects used
  for each intent kind ("quality", "text", "image", "sketch", "edit"); a weight given in a set
  overrides the aspect's own weight for that set.

A user file has the same shape; its aspects and sets are added to the built-in ones (a key that
already exists is replaced), so a user can reword an aspect, add one, or change what a set holds.
Reading the file is the caller's edge: :func:`load_aspects` takes a path, everything else takes
data.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from intuitf.errors import IntuitfError
from intuitf.evaluator.types import Aspect, Intent

#: Which aspect set each intent kind uses (an intent of kind "none" asks for quality only).
INTENT_SETS: dict[str, str] = {
    "none": "quality",
    "text": "text",
    "image": "image",
    "sketch": "sketch",
    "edit": "edit",
}


class AspectError(IntuitfError):
    """An aspect catalogue is malformed or names an unknown aspect or set."""


@dataclass
class AspectCatalogue:
    """Aspects by key, and the named sets of aspects used for each kind of intent."""

    aspects: dict[str, Aspect] = field(default_factory=dict)
    sets: dict[str, list[tuple[str, float | None]]] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "catalogue") -> AspectCatalogue:
        """Build a catalogue from its JSON form; raise :class:`AspectError` on a malformed one."""
        if not isinstance(data, Mapping):
            raise AspectError(
                f"The aspect {source} is not a JSON object.",
                'Write {"aspects": {key: {"name": ..., "description": ...}}, "sets": {...}}.',
            )
        cat = cls()
        raw_aspects = data.get("aspects", {})
        if not isinstance(raw_aspects, Mapping):
            raise AspectError(
                f'"aspects" in the aspect {source} must be an object keyed by aspect.'
            )
        for key, spec in raw_aspects.items():
            cat.aspects[key] = _aspect_from(key, spec, source)
        raw_sets = data.get("sets", {})
        if not isinstance(raw_sets, Mapping):
            raise AspectError(f'"sets" in the aspect {source} must be an object of lists.')
        for set_key, members in raw_sets.items():
            cat.sets[set_key] = _set_from(set_key, members, source)
        return cat

    def merged(self, other: AspectCatalogue) -> AspectCatalogue:
        """This catalogue with ``other``'s aspects and sets added (``other`` wins on a clash)."""
        out = AspectCatalogue(dict(self.aspects), {k: list(v) for k, v in self.sets.items()})
        out.aspects.update(other.aspects)
        out.sets.update({k: list(v) for k, v in other.sets.items()})
        out.validate()
        return out

    def validate(self) -> None:
        """Check that every set names known aspects."""
        for set_key, members in self.sets.items():
            for key, _ in members:
                if key not in self.aspects:
                    raise AspectError(
                        f"The aspect set {set_key!r} names an unknown aspect {key!r}.",
                        f'Define {key!r} under "aspects" or use one of: {", ".join(sorted(self.aspects))}.',
                    )

    def get(self, key: str) -> Aspect:
        """One aspect by key."""
        try:
            return self.aspects[key]
        except KeyError:
            raise AspectError(
                f"Unknown aspect {key!r}.",
                f"Use one of: {', '.join(sorted(self.aspects))}, or add it in an aspect file.",
            ) from None

    def for_key(self, set_key: str) -> list[Aspect]:
        """The aspects of a set ("quality", "text", "image", "sketch", "edit" or a user set)."""
        if set_key not in self.sets:
            raise AspectError(
                f"Unknown aspect set {set_key!r}.",
                f"Use one of: {', '.join(sorted(self.sets))}.",
            )
        out = []
        for key, weight in self.sets[set_key]:
            a = self.get(key)
            out.append(a if weight is None else Aspect(a.key, a.name, a.description, weight))
        return out

    def for_intent(self, intent: Intent) -> list[Aspect]:
        """The aspects that judge renderings against ``intent`` (kind "none" → quality)."""
        return self.for_key(INTENT_SETS.get(intent.kind, intent.kind))


def _aspect_from(key: str, spec: Any, source: str) -> Aspect:
    if not isinstance(key, str) or not key.replace("_", "").isalnum():
        raise AspectError(
            f"Aspect key {key!r} in the aspect {source} is not a plain identifier.",
            "Use letters, digits and underscores only (e.g. 'bone_visibility').",
        )
    if not isinstance(spec, Mapping) or not spec.get("name") or not spec.get("description"):
        raise AspectError(
            f"Aspect {key!r} in the aspect {source} needs a non-empty name and description.",
            'Write {"name": "...", "description": "..."} (and optionally "weight").',
        )
    weight = spec.get("weight", 1.0)
    if not isinstance(weight, int | float) or weight <= 0:
        raise AspectError(f"Aspect {key!r} in the aspect {source} has a weight that is not > 0.")
    return Aspect(
        key=key, name=str(spec["name"]), description=str(spec["description"]), weight=float(weight)
    )


def _set_from(set_key: str, members: Any, source: str) -> list[tuple[str, float | None]]:
    if not isinstance(members, list) or not members:
        raise AspectError(
            f"Aspect set {set_key!r} in the aspect {source} must be a non-empty list."
        )
    out: list[tuple[str, float | None]] = []
    for m in members:
        if isinstance(m, str):
            out.append((m, None))
        elif isinstance(m, Mapping) and isinstance(m.get("key"), str):
            w = m.get("weight")
            if w is not None and (not isinstance(w, int | float) or w <= 0):
                raise AspectError(
                    f"Aspect set {set_key!r} gives {m['key']!r} a weight that is not > 0."
                )
            out.append((m["key"], None if w is None else float(w)))
        else:
            raise AspectError(
                f"Aspect set {set_key!r} in the aspect {source} has an entry that is not an aspect key.",
                'Write "key" or {"key": "...", "weight": 2.0}.',
            )
    return out


_BUILTIN: AspectCatalogue | None = None


def builtin_catalogue() -> AspectCatalogue:
    """The catalogue shipped with intuitf (read once from package data)."""
    global _BUILTIN
    if _BUILTIN is None:
        text = resources.files("intuitf.intent").joinpath("aspects.json").read_text("utf-8")
        cat = AspectCatalogue.from_dict(json.loads(text), source="catalogue shipped with intuitf")
        cat.validate()
        _BUILTIN = cat
    return _BUILTIN


def load_aspects(path: str | Path, base: AspectCatalogue | None = None) -> AspectCatalogue:
    """Read a user aspect file (JSON) and return ``base`` (default: built-in) extended by it."""
    p = Path(path)
    try:
        data = json.loads(p.read_text("utf-8"))
    except FileNotFoundError:
        raise AspectError(f"Aspect file {p} does not exist.", "Check the path.") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise AspectError(f"Aspect file {p} could not be read: {exc}.") from None
    except json.JSONDecodeError as exc:
        raise AspectError(
            f"Aspect file {p} is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg}).",
            "Fix the JSON syntax; see the shipped aspects.json for the format.",
        ) from None
    user = AspectCatalogue.from_dict(data, source=f"file {p}")
    return (base or builtin_catalogue()).merged(user)


def aspects_for(key: str, catalogue: AspectCatalogue | None = None) -> list[Aspect]:
    """Aspects of the set ``key``: "quality", "text", "image", "sketch" or "edit"."""
    return (catalogue or builtin_catalogue()).for_key(key)


def aspects_for_intent(intent: Intent, catalogue: AspectCatalogue | None = None) -> list[Aspect]:
    """Aspects for an intent: none → quality, text → text, image → image, sketch, edit."""
    return (catalogue or builtin_catalogue()).for_intent(intent)
