"""Where OpenAI-compatible multimodal models live: provider presets and API-key lookup.

Every provider here speaks the chat-completions protocol, so one client reaches all of them with
a base URL and a model name. A key is looked up, in order: the explicit argument, the provider's
environment variable(s), then ``[api_keys]`` in the config file
(``$INTUITF_CONFIG`` or ``~/.config/intuitf/config.toml``)::

    [api_keys]
    openai = "sk-..."
    gemini = "..."

Keys are never logged, printed, stored or put in error messages, nor are credentials written
into a server URL (``http://user:KEY@host/v1``): :func:`redact_url` hides them.

The same file sets how long a model judge waits (``MLLMJudge`` options and the ``optimize``
command's ``--request-timeout`` / ``--answer-deadline`` take precedence)::

    [judge]
    request_timeout = 30   # seconds for one request
    answer_deadline = 60   # seconds for one answer, retries of failed requests included
    max_output_tokens = 4096   # the answer's token budget (reasoning included); default by model
    reasoning_effort = "low"   # for models that reason; "default" sends none
    max_concurrency = 8        # requests in flight at most; default by provider

and what models cost, over the built-in table (USD per million input and output tokens)::

    [prices]
    "gpt-5.4-mini" = [0.75, 4.50]
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from intuitf.errors import JudgeError
from intuitf.evaluator.profiles import DEFAULT_MODELS

#: Sent to local servers that ignore keys (the SDK refuses to run without one).
NO_KEY = "no-key-needed"


@dataclass(frozen=True)
class ProviderPreset:
    """A provider's endpoint, where its key comes from, and the model used when none is named."""

    name: str
    base_url: str
    key_env: tuple[str, ...]
    default_model: str
    needs_key: bool = True
    #: Whether the server is known to accept ``response_format`` with a JSON schema.
    structured: bool = True


PROVIDERS: dict[str, ProviderPreset] = {
    p.name: p
    for p in (
        ProviderPreset(
            "openai", "https://api.openai.com/v1", ("OPENAI_API_KEY",), DEFAULT_MODELS["openai"]
        ),
        ProviderPreset(
            "gemini",
            "https://generativelanguage.googleapis.com/v1beta/openai/",
            ("GEMINI_API_KEY", "GOOGLE_API_KEY"),
            DEFAULT_MODELS["gemini"],
        ),
        ProviderPreset(
            "ollama",
            "http://localhost:11434/v1",
            ("OLLAMA_API_KEY",),
            DEFAULT_MODELS["ollama"],
            needs_key=False,
        ),
        ProviderPreset(
            "vllm",
            "http://localhost:8000/v1",
            ("VLLM_API_KEY",),
            DEFAULT_MODELS["vllm"],
            needs_key=False,
        ),
        ProviderPreset(
            "lmstudio",
            "http://localhost:1234/v1",
            ("LMSTUDIO_API_KEY",),
            "default",
            needs_key=False,
        ),
        ProviderPreset(
            "openrouter",
            "https://openrouter.ai/api/v1",
            ("OPENROUTER_API_KEY",),
            DEFAULT_MODELS["openrouter"],
        ),
    )
}

#: The preset for a server given only by its URL.
CUSTOM = ProviderPreset("url", "", ("INTUITF_API_KEY",), "default", needs_key=False)


class Secret:
    """A value that does not show itself: repr and str are "***"; :meth:`reveal` gives it."""

    __slots__ = ("_value",)

    def __init__(self, value: str) -> None:
        self._value = value

    def reveal(self) -> str:
        return self._value

    def __repr__(self) -> str:
        return "Secret('***')"

    __str__ = __repr__

    def __reduce__(self):  # never pickled along with a judge
        raise TypeError("a Secret cannot be pickled")


#: ``scheme://userinfo@`` anywhere in a text: the userinfo (user, password or key) is secret.
_URL_USERINFO = re.compile(r"(?P<scheme>[A-Za-z][A-Za-z0-9+.\-]*://)(?P<userinfo>[^/@\s?#]+)@")
#: Query parameters that carry credentials (``?key=...`` is Gemini's style).
_SECRET_QUERY = re.compile(
    r"(?P<name>[?&](?:api[_-]?key|key|token|access[_-]?token|password|secret)=)[^&#\s]+",
    re.IGNORECASE,
)


def redact_url(text: str | None) -> str | None:
    """``text`` with credentials in any URL it contains replaced by ``***``.

    ``http://user:KEY@host/v1`` becomes ``http://user:***@host/v1``, ``http://KEY@host`` becomes
    ``http://***@host``, and ``?key=...``-style query parameters lose their values. Works on a bare
    URL, a judge spec (``URL#model``) or any message that quotes one. The one helper used
    wherever a URL is stored (run.json, journal) or shown (errors, repr, logs).
    """
    if not text:
        return text

    def userinfo(m: re.Match) -> str:
        user, sep, _ = m.group("userinfo").partition(":")
        return f"{m.group('scheme')}{user}:***@" if sep else f"{m.group('scheme')}***@"

    out = _URL_USERINFO.sub(userinfo, str(text))
    return _SECRET_QUERY.sub(lambda m: f"{m.group('name')}***", out)


def has_redacted_credentials(url: str | None) -> bool:
    """Whether ``url`` went through :func:`redact_url` and lost a credential."""
    return bool(url) and redact_url(url) == url and "***" in str(url)


def preset(name: str) -> ProviderPreset:
    """The preset named ``name``; :class:`JudgeError` if there is none."""
    try:
        return PROVIDERS[name]
    except KeyError:
        raise JudgeError(
            f"Unknown model provider {name!r}.",
            f"Use one of: {', '.join(PROVIDERS)}, or give the server's URL.",
        ) from None


def config_path() -> Path:
    """The user config file: ``$INTUITF_CONFIG`` or ``~/.config/intuitf/config.toml``."""
    env = os.environ.get("INTUITF_CONFIG")
    return Path(env) if env else Path.home() / ".config" / "intuitf" / "config.toml"


#: A dead server (it accepts the connection and never answers) fails an answer after about
#: ``DEFAULT_ANSWER_DEADLINE`` seconds: two requests of ``DEFAULT_REQUEST_TIMEOUT``.
DEFAULT_REQUEST_TIMEOUT = 30.0
DEFAULT_ANSWER_DEADLINE = 60.0


def _read_config() -> dict:
    path = config_path()
    if not path.is_file():
        return {}
    try:
        return tomllib.loads(path.read_text("utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        # The message names the file and the problem, never the file's content.
        raise JudgeError(
            f"The config file {path} could not be read ({type(exc).__name__}).",
            "Fix its TOML syntax, or set the key in the environment instead.",
        ) from None


def judge_timeouts() -> tuple[float, float]:
    """(request timeout, answer deadline) in seconds: ``[judge]`` in the config, else defaults."""
    table = _read_config().get("judge", {})
    table = table if isinstance(table, dict) else {}
    out = []
    for key, default in (
        ("request_timeout", DEFAULT_REQUEST_TIMEOUT),
        ("answer_deadline", DEFAULT_ANSWER_DEADLINE),
    ):
        value = table.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
            raise JudgeError(
                f"{key} in the config file {config_path()} must be a number of seconds above 0.",
                f"Fix it under [judge], e.g. {key} = {default:g}.",
            )
        out.append(float(value))
    return out[0], out[1]


_JUDGE_SETTINGS = {"max_output_tokens": int, "reasoning_effort": str, "max_concurrency": int}


def judge_settings() -> dict:
    """The judge settings under ``[judge]`` in the config (only those given), checked."""
    table = _read_config().get("judge", {})
    table = table if isinstance(table, dict) else {}
    out: dict = {}
    for key, kind in _JUDGE_SETTINGS.items():
        if key not in table:
            continue
        value = table[key]
        ok = isinstance(value, kind) and not isinstance(value, bool)
        if ok and kind is int and value < 1:
            ok = False
        if not ok:
            raise JudgeError(
                f"{key} under [judge] in the config file {config_path()} must be "
                + ("a whole number of at least 1." if kind is int else 'a word such as "low".'),
                "Fix it, or remove it to use the default.",
            )
        out[key] = value
    return out


def config_prices() -> dict[str, tuple[float, float]]:
    """``[prices]`` in the config: model -> (USD per 1M input tokens, per 1M output tokens)."""
    table = _read_config().get("prices", {})
    out: dict[str, tuple[float, float]] = {}
    for model, pair in (table if isinstance(table, dict) else {}).items():
        if (
            not isinstance(pair, list)
            or len(pair) != 2
            or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in pair)
            or min(pair) < 0
        ):
            raise JudgeError(
                f"The price of {model!r} under [prices] in {config_path()} must be two numbers "
                "of 0 or more: USD per million input tokens and per million output tokens.",
                f'Write it as "{model}" = [0.75, 4.50].',
            )
        out[str(model)] = (float(pair[0]), float(pair[1]))
    return out


def _key_from_config(provider: str) -> str | None:
    data = _read_config()
    keys = data.get("api_keys", {})
    value = keys.get(provider) if isinstance(keys, dict) else None
    return value if isinstance(value, str) and value else None


def resolve_api_key(p: ProviderPreset, explicit: str | None = None) -> str | None:
    """The API key for ``p``: explicit, then environment, then config file; None if absent."""
    if explicit:
        return explicit
    for var in p.key_env:
        value = os.environ.get(var)
        if value:
            return value
    return _key_from_config(p.name)


def require_api_key(p: ProviderPreset, explicit: str | None = None) -> str:
    """The key for ``p``, or :data:`NO_KEY` for local servers; JudgeError when one is needed."""
    key = resolve_api_key(p, explicit)
    if key:
        return key
    if not p.needs_key:
        return NO_KEY
    raise JudgeError(
        f"No API key for {p.name}.",
        f'Set the environment variable {p.key_env[0]}, or add `{p.name} = "..."` under '
        f"[api_keys] in {config_path()}.",
    )
