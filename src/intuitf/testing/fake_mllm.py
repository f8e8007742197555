"""A fake OpenAI-compatible multimodal model server, for tests and benchmarks.

It serves ``POST /v1/chat/completions`` and ``GET /v1/models`` over real HTTP on loopback and
answers comparison prompts like a multimodal model would, from an oracle:

- by default it prefers the candidate closer to a hidden ``target`` image (mean absolute
  difference after resizing both to 64×64);
- a ``score(image) -> float`` function (higher is better) can replace the target.

It finds the candidates the way :mod:`intuitf.evaluator.compose` labels them: the image part
after the text "Image 1 ..." is the first, after "Image 2 ..." the second, and a side-by-side
composite is split in two; images labelled with another role (reference, sketch, before the edit)
are context. Aspect keys come from the JSON schema in ``response_format`` or from the prompt's
``- [key] Name: ...`` lines. It answers in JSON when asked for a schema and in free text
otherwise, and reports usage tokens.

Realism knobs, all seeded: ``latency`` (seconds, fixed or a distribution), ``noise``
(probability of the wrong answer), ``position_bias`` (probability of preferring the first image
regardless), and ``faults`` ({kind: rate}) among :data:`FAULT_KINDS`.

**Personalities** (:data:`PERSONALITIES`, ``personality="..."``) make it behave like the servers
people use, as their documentation and users' issues describe them: ``openai-reasoning`` (rejects
``max_tokens`` and any temperature but the default, spends reasoning tokens inside the output
budget), ``gemini-thinking`` (spends the budget on thoughts billed apart, rejects an empty
assistant turn, allows few requests per window and puts its retry delay in the body, answers
404 for retired models), ``ollama`` (one request at a time, several models served),
``lmstudio`` (one slot, needs the loaded model's id) and ``vllm-one-image`` (one image per
request). Every request body is kept, images shortened, in :attr:`FakeMLLMServer.requests_log`.

Run it on its own with ``python -m intuitf.testing.fake_mllm --port 8000 --target image.png``;
``GET /stats`` returns what it saw (requests, answers, faults), the judge of what a run spent.
"""

from __future__ import annotations

import argparse
import asyncio
import hashlib
import json
import random
import re
import socket
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from PIL import Image

from intuitf.evaluator.compose import (
    FIRST_LABEL,
    PAIR_LABEL,
    SECOND_LABEL,
    decode_data_uri,
    split_side_by_side,
)

#: Faults the server can inject, each with a rate (probability per request).
FAULT_KINDS = (
    "rate_limit",  # 429 with Retry-After
    "overloaded",  # 503 with Retry-After
    "server_error",  # 500
    "hang",  # no answer until long after any sane client timeout
    "malformed",  # text that is neither JSON nor a readable answer
    "truncated",  # the JSON answer cut off half way
    "refusal",  # a polite refusal
    "blind",  # "I cannot see the image"
)


@dataclass(frozen=True)
class Personality:
    """How a kind of server behaves beyond answering (see the module notes)."""

    name: str
    #: The models it serves (GET /v1/models); the first is the one it answers as.
    models: tuple[str, ...] = ("default",)
    #: Whether a request must name one of ``models`` (404 otherwise).
    require_model: bool = False
    #: Models that answer 404 "no longer available".
    retired: tuple[str, ...] = ()
    #: Parameters answered with 400 ``unsupported_parameter``.
    reject_params: tuple[str, ...] = ()
    #: Only the default temperature (1) is accepted.
    default_temperature_only: bool = False
    #: Temperature below 1 makes the answer loop until the budget is spent (Gemini 3's warning).
    low_temperature_loops: bool = False
    #: Reasoning tokens spent before answering, by ``reasoning_effort`` ("" when none is sent).
    reasoning: tuple[tuple[str, int], ...] = ()
    #: Reasoning counted only in ``total_tokens`` (Gemini's thoughts), not ``completion_tokens``.
    reasoning_apart: bool = False
    #: Reasoning efforts accepted (others: 400 ``unsupported_value``); empty: any.
    efforts: tuple[str, ...] = ()
    #: An assistant turn without content is rejected ("parts must not be empty").
    reject_empty_parts: bool = False
    #: Requests worked on at once (others wait their turn); None: no limit.
    slots: int | None = None
    #: At most this many requests per ``window`` seconds; more get 429.
    rate: tuple[int, float] | None = None
    #: The 429's delay is in the body (Gemini's ``retryDelay``), not in ``Retry-After``.
    retry_in_body: bool = False
    #: Error bodies as a one-item list (Gemini's OpenAI-compatible endpoint).
    list_errors: bool = False
    #: Images one request may carry (400 beyond that).
    max_images: int | None = None
    #: Seconds per answer.
    latency: float = 0.0


PERSONALITIES: dict[str, Personality] = {
    p.name: p
    for p in (
        Personality(
            "openai-reasoning",
            models=("gpt-5.4-mini",),
            require_model=True,
            reject_params=("max_tokens",),
            default_temperature_only=True,
            reasoning=(("", 2500), ("minimal", 80), ("low", 600), ("medium", 2500), ("high", 6000)),
            efforts=("minimal", "low", "medium", "high"),
            latency=0.02,
        ),
        Personality(
            "gemini-thinking",
            models=("gemini-2.5-flash", "gemini-3-flash-preview"),
            require_model=True,
            retired=("gemini-2.0-flash", "gemini-1.5-flash"),
            low_temperature_loops=True,
            reasoning=(("", 3000), ("none", 0), ("low", 900), ("medium", 2000), ("high", 6000)),
            reasoning_apart=True,
            reject_empty_parts=True,
            rate=(12, 1.5),
            retry_in_body=True,
            list_errors=True,
            latency=0.02,
        ),
        Personality(
            "ollama",
            models=("llama3.2:3b", "qwen2.5vl:7b"),
            require_model=True,
            slots=1,
            latency=0.1,
        ),
        Personality(
            "lmstudio", models=("qwen2.5-vl-7b-instruct",), require_model=True, slots=1, latency=0.1
        ),
        Personality(
            "vllm-one-image",
            models=("Qwen/Qwen2.5-VL-7B-Instruct",),
            require_model=True,
            max_images=1,
            latency=0.02,
        ),
    )
}

REFUSAL_TEXT = "I'm sorry, but I can't help with comparing these images."
BLIND_TEXT = "I cannot see the image. It seems no image was attached; please upload it again."
MALFORMED_TEXT = "}{ ::: <<result pending>> ::: {{"


@dataclass(frozen=True)
class Latency:
    """Response delay: ``fixed`` seconds, ``uniform`` in [a, b], or ``lognormal`` (median a, sigma b)."""

    kind: str = "fixed"
    a: float = 0.0
    b: float = 0.0

    @classmethod
    def parse(cls, spec: Latency | float | str | tuple | None) -> Latency:
        """From 0.5, "0.5", "fixed:0.5", "uniform:0.1,0.3", "lognormal:0.5,0.4" or a tuple."""
        if spec is None:
            return cls()
        if isinstance(spec, Latency):
            return spec
        if isinstance(spec, int | float):
            return cls("fixed", float(spec))
        if isinstance(spec, tuple):
            kind, *vals = spec
            vals = [*vals, 0.0, 0.0]
            return cls(str(kind), float(vals[0]), float(vals[1]))
        text = str(spec).strip()
        if ":" not in text:
            return cls("fixed", float(text))
        kind, rest = text.split(":", 1)
        vals = [float(v) for v in rest.split(",") if v.strip()] + [0.0, 0.0]
        if kind not in ("fixed", "uniform", "lognormal"):
            raise ValueError(f"unknown latency distribution {kind!r}")
        return cls(kind, vals[0], vals[1])

    def sample(self, rng: random.Random) -> float:
        if self.kind == "uniform":
            return rng.uniform(self.a, self.b)
        if self.kind == "lognormal":
            return self.a * float(np.exp(rng.gauss(0.0, self.b))) if self.a > 0 else 0.0
        return self.a


@dataclass
class ServerStats:
    """What the server saw: requests, concurrency, faults injected, answers given."""

    requests: int = 0
    in_flight: int = 0
    max_in_flight: int = 0
    answered: int = 0
    faults: dict[str, int] = field(default_factory=dict)
    first_preferred: int = 0
    second_preferred: int = 0
    undecided: int = 0
    input_tokens: int = 0
    output_tokens: int = 0
    structured_requests: int = 0
    #: Requests that continue a conversation (an earlier answer and a follow-up message).
    follow_ups: int = 0
    #: Requests answered with an error by the personality's rules, by reason.
    rejected: dict[str, int] = field(default_factory=dict)
    #: Reasoning tokens spent, and answers left empty because the budget went on reasoning.
    reasoning_tokens: int = 0
    empty_answers: int = 0
    #: Structure-atlas requests among :attr:`requests` (a model-judged run names its
    #: volume's structures once before its first generation).
    atlas_requests: int = 0


def _small(img: np.ndarray) -> np.ndarray:
    return np.asarray(
        Image.fromarray(img).convert("RGB").resize((64, 64), Image.Resampling.BILINEAR), np.float32
    )


class TargetOracle:
    """Scores an image by closeness to a target: minus the mean absolute difference at 64×64."""

    def __init__(self, target: np.ndarray) -> None:
        self._t = _small(np.asarray(target, np.uint8)[..., :3])

    def __call__(self, image: np.ndarray) -> float:
        return -float(np.mean(np.abs(_small(image) - self._t)))


class FakeMLLMServer:
    """A real HTTP server on 127.0.0.1 that answers like a multimodal model (context manager).

    ``with FakeMLLMServer(target=img) as srv: judge = MLLMJudge("default", base_url=srv.base_url)``.
    ``port=0`` picks a free port. ``structured=False`` makes it reject ``response_format`` with
    HTTP 400, like servers without structured output; ``structured="json_object"`` takes JSON
    mode but not a schema. ``retry_after`` is the delay it asks for with 429/503;
    ``hang_seconds`` how long a hang lasts. ``personality`` (a name in :data:`PERSONALITIES` or a
    :class:`Personality`) adds a real server's behaviour; its latency applies unless ``latency``
    is given.
    """

    def __init__(
        self,
        target: np.ndarray | None = None,
        score: Callable[[np.ndarray], float] | None = None,
        *,
        latency: Latency | float | str | tuple | None = 0.0,
        noise: float = 0.0,
        position_bias: float = 0.0,
        faults: Mapping[str, float] | None = None,
        seed: int = 0,
        port: int = 0,
        host: str = "127.0.0.1",
        structured: bool | str = True,
        retry_after: float = 0.05,
        hang_seconds: float = 30.0,
        model: str = "default",
        personality: str | Personality | None = None,
        labeller: Any = None,
    ) -> None:
        #: Answers structure-atlas requests (:class:`intuitf.testing.fake_labels.LabelNamer`);
        #: without one, an atlas request is answered with no names.
        self.labeller = labeller
        if score is None and target is None:
            raise ValueError("give a target image or a score function")
        self.score = score if score is not None else TargetOracle(target)  # type: ignore[arg-type]
        self.latency = Latency.parse(latency)
        self.noise = float(noise)
        self.position_bias = float(position_bias)
        self.faults = dict(faults or {})
        unknown = set(self.faults) - set(FAULT_KINDS)
        if unknown:
            raise ValueError(f"unknown fault kinds {sorted(unknown)}; known: {FAULT_KINDS}")
        if sum(self.faults.values()) > 1.0 + 1e-9:
            raise ValueError("fault rates add up to more than 1")
        self.seed = int(seed)
        self.host = host
        self.port = int(port)
        self.structured = structured
        self.retry_after = float(retry_after)
        self.hang_seconds = float(hang_seconds)
        if isinstance(personality, str):
            if personality not in PERSONALITIES:
                raise ValueError(
                    f"unknown personality {personality!r}; known: {', '.join(PERSONALITIES)}"
                )
            personality = PERSONALITIES[personality]
        self.personality: Personality = personality or Personality("plain", models=(model,))
        if personality is not None and latency == 0.0:
            self.latency = Latency.parse(self.personality.latency)
        self.model = self.personality.models[-1] if personality is not None else model
        #: Every request body, images shortened to their size (the first 200).
        self.requests_log: list[dict] = []
        self._slots: asyncio.Semaphore | None = None
        self._window: list[float] = []
        self.stats = ServerStats()
        self._seen: dict[str, int] = {}
        self._lock = threading.Lock()
        self._server: Any = None
        self._thread: threading.Thread | None = None
        self.app = self._build_app()

    # -- lifecycle ----------------------------------------------------------------------------

    @property
    def base_url(self) -> str:
        return f"http://{self.host}:{self.port}/v1"

    def start(self) -> FakeMLLMServer:
        """Start serving in a background thread; returns when the server accepts connections."""
        import uvicorn

        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((self.host, self.port))
        self.port = sock.getsockname()[1]
        config = uvicorn.Config(
            self.app,
            log_level="warning",
            access_log=False,
            lifespan="off",
            timeout_graceful_shutdown=1,
            backlog=2048,
        )
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(
            target=self._server.run, kwargs={"sockets": [sock]}, daemon=True, name="fake-mllm"
        )
        self._thread.start()
        deadline = time.monotonic() + 10
        while not self._server.started:
            if not self._thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError("the fake model server did not start")
            time.sleep(0.01)
        return self

    def stop(self) -> None:
        """Stop the server (requests still hanging are dropped)."""
        if self._server is not None:
            self._server.should_exit = True
            self._server.force_exit = True
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._server = None
        self._thread = None

    def __enter__(self) -> FakeMLLMServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- the HTTP app -------------------------------------------------------------------------

    def _build_app(self) -> Any:
        app = FastAPI(title="intuitf fake multimodal model")

        @app.get("/v1/models")
        async def models() -> dict:
            return {
                "object": "list",
                "data": [
                    {"id": m, "object": "model", "owned_by": "intuitf"}
                    for m in self.personality.models
                ],
            }

        @app.get("/stats")
        async def stats() -> dict:
            """What the server saw so far (requests, answers, faults ...): the judge of spending."""
            with self._lock:
                return json.loads(json.dumps(self.stats.__dict__))

        @app.post("/v1/chat/completions")
        async def chat(request: Request) -> Any:
            body = await request.json()
            with self._lock:
                if len(self.requests_log) < 200:
                    self.requests_log.append(shorten_images(body))
                if any(m.get("role") == "assistant" for m in body.get("messages", [])):
                    self.stats.follow_ups += 1
                self.stats.requests += 1
                self.stats.in_flight += 1
                self.stats.max_in_flight = max(self.stats.max_in_flight, self.stats.in_flight)
            try:
                rule = self._rules(body)
                if rule is None and _atlas_request(body):
                    # Without a labeller, a model that cannot name anything: no names.
                    names = self.labeller.answer(body) if self.labeller else '{"names": {}}'
                    rule = 200, _completion(body, names, self.model), {}
                    with self._lock:
                        self.stats.answered += 1
                        self.stats.atlas_requests += 1
                if rule is not None:
                    status, payload, headers = rule
                elif self.personality.slots:
                    if self._slots is None:
                        self._slots = asyncio.Semaphore(self.personality.slots)
                    async with self._slots:
                        status, payload, headers = await self._handle(body)
                else:
                    status, payload, headers = await self._handle(body)
                if status >= 400 and self.personality.list_errors:
                    payload = [payload]  # type: ignore[assignment]
            finally:
                with self._lock:
                    self.stats.in_flight -= 1
            return JSONResponse(payload, status_code=status, headers=headers)

        return app

    def _reject(self, reason: str, status: int, message: str, code: str, param: str | None = None):
        with self._lock:
            self.stats.rejected[reason] = self.stats.rejected.get(reason, 0) + 1
        err = _error(message, code)
        err["error"]["param"] = param
        return status, err, {}

    def _rules(self, body: dict) -> tuple[int, dict, dict] | None:
        """The personality's answer to a request it does not take, or None to answer it."""
        p = self.personality
        model = str(body.get("model", ""))
        if model in p.retired:
            return self._reject(
                "retired",
                404,
                f"models/{model} is no longer available to new users. Please update your "
                "code to use a newer model.",
                "not_found",
            )
        if p.require_model and model not in p.models:
            return self._reject(
                "model", 404, f"The model `{model}` does not exist or is not loaded.", "not_found"
            )
        for param in p.reject_params:
            if param in body:
                return self._reject(
                    param,
                    400,
                    f"Unsupported parameter: '{param}' is not supported with this model. Use "
                    "'max_completion_tokens' instead.",
                    "unsupported_parameter",
                    param,
                )
        temp = body.get("temperature")
        if p.default_temperature_only and temp is not None and float(temp) != 1.0:
            return self._reject(
                "temperature",
                400,
                f"Unsupported value: 'temperature' does not support {temp} with this model. "
                "Only the default (1) value is supported.",
                "unsupported_value",
                "temperature",
            )
        effort = body.get("reasoning_effort")
        if effort is not None and p.efforts and effort not in p.efforts:
            listed = ", ".join(f"'{e}'" for e in p.efforts)
            return self._reject(
                "reasoning_effort",
                400,
                f"Unsupported value: '{effort}' is not supported with the '{model}' model. "
                f"Supported values are: {listed}.",
                "unsupported_value",
                "reasoning_effort",
            )
        if p.reject_empty_parts:
            for i, m in enumerate(body.get("messages", [])):
                if m.get("role") == "assistant" and not m.get("content"):
                    return self._reject(
                        "empty parts",
                        400,
                        f"* GenerateContentRequest.contents[{i}].parts: contents.parts must not "
                        "be empty.",
                        "INVALID_ARGUMENT",
                    )
        if p.max_images is not None:
            n = sum(
                1
                for m in body.get("messages", [])
                if isinstance(m.get("content"), list)
                for part in m["content"]
                if isinstance(part, dict) and part.get("type") == "image_url"
            )
            if n > p.max_images:
                return self._reject(
                    "images",
                    400,
                    f"At most {p.max_images} image(s) may be provided in one request.",
                    "BadRequestError",
                )
        if p.rate is not None:
            count, window = p.rate
            now = time.monotonic()
            with self._lock:
                self._window = [t for t in self._window if now - t < window]
                if len(self._window) >= count:
                    wait = window - (now - self._window[0])
                    self.stats.rejected["rate"] = self.stats.rejected.get("rate", 0) + 1
                    self.stats.faults["rate_limit"] = self.stats.faults.get("rate_limit", 0) + 1
                    err = _error(
                        "You exceeded your current quota, please check your plan and billing "
                        "details.",
                        "RESOURCE_EXHAUSTED",
                    )
                    if p.retry_in_body:
                        err["error"]["details"] = [
                            {
                                "@type": "type.googleapis.com/google.rpc.RetryInfo",
                                "retryDelay": f"{wait:.2f}s",
                            }
                        ]
                        return 429, err, {}
                    return 429, err, {"retry-after": f"{wait:.2f}"}
                self._window.append(now)
        return None

    def _rng_for(self, body: dict) -> random.Random:
        """A generator seeded by the request's content and how often it was seen before.

        Answers do not depend on the order in which concurrent requests arrive, and a retried
        request draws fresh dice (so a fault is not repeated forever).
        """
        digest = hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()
        with self._lock:
            n = self._seen.get(digest, 0)
            self._seen[digest] = n + 1
        return random.Random(f"{self.seed}:{digest}:{n}")

    def _fault(self, rng: random.Random) -> str | None:
        u = rng.random()
        acc = 0.0
        for kind in FAULT_KINDS:
            acc += self.faults.get(kind, 0.0)
            if u < acc:
                with self._lock:
                    self.stats.faults[kind] = self.stats.faults.get(kind, 0) + 1
                return kind
        return None

    async def _handle(self, body: dict) -> tuple[int, dict, dict]:
        rng = self._rng_for(body)
        fault = self._fault(rng)
        # Draw every random number before awaiting, so answers do not depend on scheduling.
        delay = self.latency.sample(rng)
        u_bias, u_noise = rng.random(), rng.random()
        if fault == "hang":
            await self._hang()
        if delay > 0:
            await asyncio.sleep(delay)
        if fault in ("rate_limit", "overloaded"):
            code = 429 if fault == "rate_limit" else 503
            return (
                code,
                _error(f"fake {fault}", "rate_limit_exceeded" if code == 429 else "overloaded"),
                {"retry-after": f"{self.retry_after:g}"},
            )
        if fault == "server_error":
            return 500, _error("fake internal error", "server_error"), {}
        wants_json = _wants_schema(body)
        json_mode = _wants_json_object(body)
        if wants_json or json_mode:
            if self.structured is False:
                err = _error(
                    "response_format is not supported by this server", "invalid_request_error"
                )
                err["error"]["param"] = "response_format"
                return 400, err, {}
            if wants_json and self.structured == "json_object":
                err = _error(
                    "response_format type json_schema is not supported; use json_object",
                    "invalid_request_error",
                )
                err["error"]["param"] = "response_format"
                return 400, err, {}
            with self._lock:
                self.stats.structured_requests += 1
        try:
            text_parts, first, second = _read_request(body)
        except ValueError as exc:
            return 400, _error(f"could not read the request: {exc}", "invalid_request_error"), {}
        prompt = "\n".join(text_parts)
        keys = _aspect_keys(body, prompt)
        if fault == "refusal":
            content = REFUSAL_TEXT
        elif fault == "blind":
            content = BLIND_TEXT
        elif fault == "malformed":
            content = MALFORMED_TEXT
        else:
            choice = self._decide(first, second, u_bias, u_noise)
            content = _answer(
                keys,
                choice,
                wants_json or json_mode,
                "reference_description" in _schema_props(body),
            )
            if fault == "truncated":
                content = content[: max(1, len(content) // 2)]
        n_images = 2 + sum(1 for t in text_parts if t.startswith(("Reference", "Sketch", "Before")))
        tin = len(prompt) // 4 + 85 * n_images
        tout = max(1, len(content) // 4)
        content, tout, thought, finish = self._reason(body, content, tout)
        with self._lock:
            self.stats.answered += 1
            self.stats.input_tokens += tin
            self.stats.output_tokens += tout + thought
            self.stats.reasoning_tokens += thought
            self.stats.empty_answers += not content
        p = self.personality
        completion = tout if p.reasoning_apart else tout + thought
        usage: dict[str, Any] = {
            "prompt_tokens": tin,
            "completion_tokens": completion,
            "total_tokens": tin + tout + thought,
        }
        if thought and not p.reasoning_apart:
            usage["completion_tokens_details"] = {"reasoning_tokens": thought}
        return (
            200,
            {
                "id": f"chatcmpl-fake-{self.stats.requests}",
                "object": "chat.completion",
                "created": int(time.time()),
                "model": body.get("model", self.model),
                "choices": [
                    {
                        "index": 0,
                        "message": {"role": "assistant", "content": content},
                        "finish_reason": finish,
                    }
                ],
                "usage": usage,
            },
            {},
        )

    def _reason(self, body: dict, content: str, tout: int) -> tuple[str, int, int, str]:
        """(content, answer tokens, reasoning tokens, finish reason) under the output budget:
        a reasoning model thinks first, and when the budget runs out the answer is empty."""
        p = self.personality
        budget = body.get("max_completion_tokens") or body.get("max_tokens")
        temp = body.get("temperature")
        model = str(body.get("model", ""))
        if p.low_temperature_loops and temp is not None and float(temp) < 1.0:
            if model.startswith("gemini-3") and budget:
                loop = "The first image shows the bone; the first image shows the bone. "
                text = (loop * (int(budget) // 12 + 1))[: int(budget) * 4]
                return text, int(budget), 0, "length"
        thought = dict(p.reasoning).get(str(body.get("reasoning_effort") or ""), 0)
        if not p.reasoning:
            thought = 0
        if budget is not None and thought + tout > int(budget):
            return "", 0, min(thought, int(budget)), "length"
        return content, tout, thought, "stop"

    async def _hang(self) -> None:
        """Wait ``hang_seconds``, or until the server stops (so stopping it stays quiet)."""
        end = time.monotonic() + self.hang_seconds
        while time.monotonic() < end:
            server = self._server
            if server is None or server.should_exit:
                return
            await asyncio.sleep(min(0.05, max(0.0, end - time.monotonic())))

    def _decide(self, first: np.ndarray, second: np.ndarray, u_bias: float, u_noise: float) -> str:
        choice = oracle_choice(
            lambda: (self.score(first), self.score(second)),
            u_bias,
            u_noise,
            position_bias=self.position_bias,
            noise=self.noise,
        )
        with self._lock:
            if choice == "first":
                self.stats.first_preferred += 1
            elif choice == "second":
                self.stats.second_preferred += 1
            else:
                self.stats.undecided += 1
        return choice


def oracle_choice(
    scores: Callable[[], tuple[float, float]],
    u_bias: float,
    u_noise: float,
    *,
    position_bias: float,
    noise: float,
) -> str:
    """How the fake model answers: "first", "second" or "cannot decide".

    With probability ``position_bias`` (``u_bias`` below it) it prefers the first image
    without looking; otherwise the higher of ``scores()`` wins (equal: cannot decide), and
    with probability ``noise`` that answer is flipped. ``u_bias`` and ``u_noise`` are uniform
    draws in [0, 1) supplied by the caller, so the caller owns the randomness.
    """
    if u_bias < position_bias:
        return "first"
    s1, s2 = scores()
    choice = "first" if s1 > s2 else "second" if s2 > s1 else "cannot decide"
    if choice != "cannot decide" and u_noise < noise:
        choice = "second" if choice == "first" else "first"
    return choice


def _atlas_request(body: dict) -> bool:
    from intuitf.testing.fake_labels import is_atlas_request

    return is_atlas_request(body)


def _completion(body: dict, content: str, model: str) -> dict:
    """A plain chat completion carrying ``content``."""
    return {
        "id": "fake-atlas", "object": "chat.completion", "created": int(time.time()),
        "model": body.get("model", model),
        "choices": [{"index": 0, "message": {"role": "assistant", "content": content},
                     "finish_reason": "stop"}],
        "usage": {"prompt_tokens": 0, "completion_tokens": len(content) // 4,
                  "total_tokens": len(content) // 4},
    }  # fmt: skip


def _error(message: str, kind: str) -> dict:
    return {"error": {"message": message, "type": kind, "code": kind}}


def shorten_images(body: dict) -> dict:
    """``body`` with each image's data URI replaced by its type and size (for logs, fixtures)."""

    def short(value: Any) -> Any:
        if isinstance(value, dict):
            return {k: short(v) for k, v in value.items()}
        if isinstance(value, list):
            return [short(v) for v in value]
        if isinstance(value, str) and value.startswith("data:") and ";base64," in value:
            head, data = value.split(";base64,", 1)
            return f"{head};base64,<{len(data) * 3 // 4} bytes>"
        return value

    return short(body)


def _wants_json_object(body: dict) -> bool:
    rf = body.get("response_format")
    return isinstance(rf, dict) and rf.get("type") == "json_object"


def _wants_schema(body: dict) -> bool:
    rf = body.get("response_format")
    return isinstance(rf, dict) and rf.get("type") == "json_schema"


def _schema_props(body: dict) -> dict:
    if not _wants_schema(body):
        return {}
    schema = body["response_format"].get("json_schema", {}).get("schema", {})
    return schema.get("properties", {}) if isinstance(schema, dict) else {}


def _aspect_keys(body: dict, prompt: str) -> list[str]:
    aspects = _schema_props(body).get("aspects", {})
    if isinstance(aspects, dict) and aspects.get("properties"):
        return list(aspects["properties"])
    keys = re.findall(r"^- \[([A-Za-z0-9_]+)\]", prompt, re.MULTILINE)
    return keys or ["overall"]


def _read_request(body: dict) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The text parts of the user turn and the two candidate images, found by their labels."""
    texts: list[str] = []
    first = second = None
    label = ""
    for msg in body.get("messages", []):
        if msg.get("role") != "user":
            continue
        content = msg.get("content")
        if isinstance(content, str):
            texts.append(content)
            continue
        for part in content or []:
            if part.get("type") == "text":
                label = str(part.get("text", ""))
                texts.append(label)
            elif part.get("type") == "image_url":
                url = part.get("image_url", {})
                url = url.get("url", "") if isinstance(url, dict) else str(url)
                img = decode_data_uri(url)
                if label.startswith(PAIR_LABEL):
                    first, second = split_side_by_side(img)
                elif label.startswith(FIRST_LABEL):
                    first = img
                elif label.startswith(SECOND_LABEL):
                    second = img
    if first is None or second is None:
        raise ValueError("no images labelled 'Image 1' and 'Image 2'")
    return texts, first, second


def _answer(keys: list[str], choice: str, as_json: bool, with_reference: bool) -> str:
    if as_json:
        obj: dict[str, Any] = {}
        if with_reference:
            obj["reference_description"] = "The reference shows its structures in the colours seen."
        obj["aspects"] = {
            k: {
                "analysis": f"On {k}, the {choice} image looks better."
                if choice != "cannot decide"
                else "Equal.",
                "choice": choice,
            }
            for k in keys
        }
        return json.dumps(obj)
    lines = [f"{k}: Image 1 and Image 2 compared; {choice} is better." for k in keys]
    lines.append("")
    lines.append("Final answer:")
    lines += [f"[{k}]: {choice}" for k in keys]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Run the fake server in the foreground until interrupted."""
    parser = argparse.ArgumentParser(
        prog="python -m intuitf.testing.fake_mllm",
        description="A fake OpenAI-compatible multimodal model that prefers images close to a target.",
    )
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument(
        "--target", help="PNG/JPEG image the oracle prefers (default: a bright image)"
    )
    parser.add_argument(
        "--latency", default="0", help='seconds, or "uniform:A,B" or "lognormal:MEDIAN,SIGMA"'
    )
    parser.add_argument("--noise", type=float, default=0.0, help="probability of a wrong answer")
    parser.add_argument(
        "--position-bias", type=float, default=0.0, help="probability of preferring Image 1"
    )
    parser.add_argument(
        "--fault-rate",
        action="append",
        default=[],
        metavar="KIND=RATE",
        help=f"inject a fault with a rate; KIND is one of {', '.join(FAULT_KINDS)} (repeatable)",
    )
    parser.add_argument(
        "--retry-after", type=float, default=1.0, help="seconds asked for with 429/503"
    )
    parser.add_argument(
        "--no-structured", action="store_true", help="reject response_format (HTTP 400)"
    )
    parser.add_argument(
        "--personality",
        choices=sorted(PERSONALITIES),
        help="behave like a real server (see the module notes)",
    )
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    faults = {}
    for item in args.fault_rate:
        kind, _, rate = item.partition("=")
        if kind not in FAULT_KINDS:
            parser.error(f"unknown fault kind {kind!r}; use one of {', '.join(FAULT_KINDS)}")
        try:
            faults[kind] = float(rate)
        except ValueError:
            parser.error(f"--fault-rate {item!r}: RATE must be a number")
        if not 0.0 <= faults[kind] <= 1.0:
            parser.error(f"--fault-rate {item!r}: RATE must be within 0..1")
    if sum(faults.values()) > 1.0 + 1e-9:
        given = ", ".join(f"{k}={v:g}" for k, v in faults.items())
        parser.error(
            f"--fault-rate values add up to {sum(faults.values()):g} ({given}); each request "
            "gets at most one fault, so together they must be at most 1"
        )
    for flag, value in (("--noise", args.noise), ("--position-bias", args.position_bias)):
        if not 0.0 <= value <= 1.0:
            parser.error(f"{flag} is a probability within 0..1, got {value:g}")
    if args.target:
        try:
            with Image.open(args.target) as im:
                target = np.asarray(im.convert("RGB"))
        except OSError as exc:
            parser.error(f"cannot read --target {args.target}: {exc}")
        score = None
    else:
        target, score = None, lambda img: float(np.mean(img))
    try:
        latency = Latency.parse(args.latency)
    except ValueError as exc:
        parser.error(f"--latency: {exc}")
    server = FakeMLLMServer(
        target,
        score,
        latency=latency,
        noise=args.noise,
        position_bias=args.position_bias,
        faults=faults,
        seed=args.seed,
        port=args.port,
        host=args.host,
        structured=not args.no_structured,
        retry_after=args.retry_after,
        personality=args.personality,
    )
    server.start()
    print(f"fake multimodal model at {server.base_url} (Ctrl-C to stop)", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
        print(json.dumps(server.stats.__dict__), flush=True)


if __name__ == "__main__":
    main()
