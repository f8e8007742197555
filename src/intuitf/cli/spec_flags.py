"""A run spec's field errors in the words of the command line: ``settings.population`` is
``--population``. The spec names every bad field (:class:`~intuitf.session.spec.SpecError`);
the commands show each under the flag that set it."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from intuitf.errors import IntuitfError

#: Spec field path (or its first parts) -> the flag that sets it.
FLAGS: dict[str, str] = {
    "settings.population": "--population",
    "settings.generations": "--generations",
    "settings.n_gaussians": "--gaussians",
    "settings.seed": "--seed",
    "settings.explorer": "--explorer",
    "settings.protocol": "--protocol",
    "settings.image_size": "--size",
    "settings.output_size": "--output-size",
    "settings.top_k": "--top",
    "settings.shading": "--shading/--no-shading",
    "settings.palette_hint": "--palette/--no-palette",
    "settings.material_hints": "--hints/--no-hints",
    "settings.fit_sketch": "--fit-sketch/--no-fit-sketch",
    "settings.device": "--device",
    "settings.camera": "--azimuth/--elevation",
    "judge.spec": "--evaluator",
    "judge.base_url": "--base-url",
    "judge.budget_usd": "--budget-usd",
    "judge.budget_calls": "--budget-calls",
    "judge.options.timeout": "--request-timeout",
    "judge.options.deadline": "--answer-deadline",
    "judge.options.max_concurrency": "--max-concurrency",
    "judge.options.max_output_tokens": "--max-output-tokens",
    "judge.options.reasoning_effort": "--reasoning-effort",
    "intent.text": "--text",
    "intent.about": "--about",
    "intent.reference": "--image",
    "intent.sketch": "--sketch",
    "intent.base": "--on",
    "intent.selected": "--select",
    "volume": "VOLUME",
    "initial": "--start-from",
}


def flag_for(path: str) -> str:
    """The flag for a spec field path (the longest known prefix), else the path itself."""
    parts = path.split(".")
    for n in range(len(parts), 0, -1):
        flag = FLAGS.get(".".join(parts[:n]))
        if flag is not None:
            return flag
    return path


@contextmanager
def flag_errors() -> Iterator[None]:
    """Turn a :class:`SpecError` raised inside into one error that names the flags."""
    from intuitf.session.spec import SpecError

    try:
        yield
    except SpecError as exc:
        lines: dict[str, str] = {}
        for path, msg in exc.fields.items():
            lines.setdefault(flag_for(path), msg)
        raise IntuitfError(
            "Invalid options: " + "; ".join(f"{flag}: {msg}" for flag, msg in lines.items()) + ".",
            "Fix the options named above (see --help); nothing was written.",
        ) from None
