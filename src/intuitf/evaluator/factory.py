"""Making a judge from a short spec string, as the command line and config files give it.

Specs:

- ``"metric"``: the offline :class:`~intuitf.evaluator.metric.MetricJudge` (no model, no network);
- ``"PROVIDER:MODEL"`` for PROVIDER in openai, gemini, ollama, vllm, lmstudio, openrouter
  (``"PROVIDER"`` alone uses the provider's default model);
- ``"http(s)://host:port/v1"`` or ``"http(s)://host:port/v1#MODEL"``: any OpenAI-compatible
  server (model from ``#MODEL``, else the ``model`` option, else the one the server lists at
  ``GET /v1/models``, else "default").

Cloud providers need an API key (environment variable or config file); local servers do not.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

from intuitf.errors import JudgeError
from intuitf.evaluator.budget import Budget
from intuitf.evaluator.cache import VerdictCache
from intuitf.evaluator.providers import PROVIDERS, redact_url
from intuitf.evaluator.types import Judge

_SPEC_HINT = (
    "Use 'metric', PROVIDER:MODEL with PROVIDER one of "
    + ", ".join(PROVIDERS)
    + ", or a server URL such as http://localhost:8000/v1#MODEL."
)


def make_judge(
    spec: str,
    *,
    cache: VerdictCache | None = None,
    budget: Budget | None = None,
    **options: Any,
) -> Judge:
    """A judge for ``spec`` (see the module docs); ``options`` go to the judge's constructor."""
    if not isinstance(spec, str) or not spec.strip():
        raise JudgeError("No judge given.", _SPEC_HINT)
    spec = spec.strip()
    if spec == "metric":
        from intuitf.evaluator.metric import MetricJudge

        return MetricJudge(**options)

    from intuitf.evaluator.mllm import MLLMJudge

    if spec.startswith(("http://", "https://")):
        url, _, named = spec.partition("#")
        options.pop("base_url", None)  # the spec is the URL
        served = named or options.pop("model", None) or None  # None: GET /v1/models says
        options.pop("model", None)
        return MLLMJudge(served, base_url=url, cache=cache, budget=budget, **options)
    provider, _, model = spec.partition(":")
    provider = provider.lower()
    if provider not in PROVIDERS:
        raise JudgeError(f"Unknown judge {spec!r}.", _SPEC_HINT)
    model = model or options.pop("model", None)
    options.pop("model", None)
    return MLLMJudge(model or None, provider=provider, cache=cache, budget=budget, **options)


# -- the judge of a run, as recorded in its run.json --------------------------------------------


def _is_url(spec: str | None) -> bool:
    return bool(spec) and str(spec).startswith(("http://", "https://"))


def judge_record(spec: str, base_url: str | None, generation: int = 0) -> dict:
    """What run.json keeps about a run's judge: spec and URL with credentials redacted, and the
    list of judges used (each with the generation it started at)."""
    entry = {
        "evaluator": redact_url(spec),
        "base_url": redact_url(base_url),
        "from_generation": int(generation),
    }
    return {"evaluator": entry["evaluator"], "base_url": entry["base_url"], "judges": [entry]}


def resume_judge_spec(
    record: dict, evaluator: str | None = None, base_url: str | None = None
) -> tuple[str, str | None, bool]:
    """The judge spec and base URL to resume a run with, and whether the run moves.

    ``record`` is the run's run.json. A new ``evaluator`` replaces the recorded one; a new
    ``base_url`` replaces the server address, also when the recorded evaluator is a URL (its
    ``#MODEL`` is kept). A recorded address whose credentials were redacted must be given again.
    """
    old_spec = str(record.get("evaluator") or "metric")
    old_url = record.get("base_url") or None
    spec = evaluator.strip() if evaluator and evaluator.strip() else old_spec
    if evaluator and base_url is None:
        # The recorded server address goes with the recorded provider only.
        same_provider = spec.partition(":")[0] == old_spec.partition(":")[0] and not _is_url(spec)
        url = old_url if same_provider else None
    else:
        url = base_url or old_url
    if base_url and _is_url(spec):
        _, _, model = spec.partition("#")
        spec = base_url.strip() + (f"#{model}" if model else "")
        url = None
    for value in (spec, url):
        if value and "***" in value and redact_url(value) == value:
            raise JudgeError(
                "This run's model server address held credentials, which intuitf does not store.",
                "Give the address again when resuming: intuitf optimize --resume RUN "
                "--base-url http://USER:KEY@HOST/v1 (or put the key in INTUITF_API_KEY).",
            )
    moved = (redact_url(spec), redact_url(url)) != (redact_url(old_spec), redact_url(old_url))
    if spec == "metric":
        url = None
    return spec, url, moved


def record_judge_move(record: dict, spec: str, base_url: str | None, generation: int) -> dict:
    """Note in ``record`` (run.json's dict, changed in place) that the run now uses this judge
    from ``generation`` on; returns the new history entry."""
    history = list(record.get("judges") or [])
    if not history:  # a run recorded before the history existed: its first judge from gen 0
        history.append(
            {
                "evaluator": redact_url(record.get("evaluator") or "metric"),
                "base_url": redact_url(record.get("base_url")),
                "from_generation": 0,
            }
        )
    new = judge_record(spec, base_url, generation)
    entry = new["judges"][0]
    history.append(entry)
    record.update(evaluator=new["evaluator"], base_url=new["base_url"], judges=history)
    return entry


def note_adaptation(record: dict, note: dict) -> dict:
    """Add to ``record`` (run.json's dict, changed in place) what the judge changed because its
    server said so (``MLLMJudge.adaptations``); returns ``record``."""
    entries = list(record.get("judge_adaptations") or [])
    entries.append({k: redact_url(v) if isinstance(v, str) else v for k, v in note.items()})
    record["judge_adaptations"] = entries
    return record


def adaptation_recorder(run_dir: str | os.PathLike | None) -> Callable[[dict], None] | None:
    """A judge's ``on_adapt`` that records each adaptation in ``run_dir``'s run.json (None
    without a run folder). A run.json not yet written is left alone (the note stays in the log)."""
    if run_dir is None:
        return None

    def record(note: dict) -> None:
        from intuitf.session.rundir import RunDirectory

        rd = RunDirectory(run_dir)
        if rd.run_json.exists():
            rd.write_run(note_adaptation(rd.read_run(), note))

    return record
