"""The server's guard: a per-launch token, Host and Origin checks, a strict CSP, no secrets out.

Every request (the page, static files, ``/api/*``, ``/openapi.json``, ``/docs`` and the
WebSocket) must carry the token: ``?token=...``, an ``Authorization: token ...`` header or
the ``intuitf_token`` cookie, which is set (HttpOnly, SameSite=Strict) on a request that
carried a valid ``?token=``. The Host header must name an allowed host (DNS rebinding);
a state-changing request or a WebSocket handshake whose Origin is present must come from
the same origin (no cross-site requests; no CORS headers are ever sent). Every response
carries a strict Content-Security-Policy. Values of API keys found in the environment or
in the config file are blanked out of every text response, whatever produced it.

A pure ASGI middleware, so that it covers WebSockets as well as HTTP.
"""

from __future__ import annotations

import json
import logging
import os
import re
import secrets
from collections.abc import Iterable
from http.cookies import SimpleCookie
from urllib.parse import parse_qs, urlsplit

COOKIE = "intuitf_token"

CSP = (
    "default-src 'self'; img-src 'self' data: blob:; connect-src 'self'; style-src 'self'; "
    "script-src 'self'; object-src 'none'; frame-ancestors 'none'; base-uri 'none'"
)

SECURITY_HEADERS = [
    (b"content-security-policy", CSP.encode()),
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"no-referrer"),
    (b"cross-origin-opener-policy", b"same-origin"),
    (b"cross-origin-resource-policy", b"same-origin"),
]

SAFE_METHODS = {"GET", "HEAD", "OPTIONS"}

#: Environment variables whose values are secrets (never sent to the page).
_SECRET_NAME = re.compile(r"(API_?KEY|SECRET|TOKEN|PASSWORD|PASSWD|CREDENTIAL)", re.I)
#: Shorter values are too likely to occur in ordinary text to blank them out.
_MIN_SECRET = 8

DEFAULT_HOSTS = ("127.0.0.1", "localhost", "[::1]")

TOO_LARGE_HINT = "Upload a smaller file, or start the server with a larger --max-upload-mb."


def too_large(limit: int) -> str:
    """The one message of a refused upload, for a limit of ``limit`` bytes."""
    return f"The upload is larger than the limit of {limit / (1024 * 1024):g} MiB."


class _RefusedHandshakes(logging.Filter):
    """Drops uvicorn's "returned without completing handshake" error for a WebSocket
    handshake this middleware refused on purpose (answered 401/403/400 over HTTP): uvicorn's
    sans-io protocol logs it after any such answer. Only as many records are dropped as
    handshakes were refused, so a real failure to complete one is still logged."""

    MESSAGE = "ASGI callable returned without completing handshake"

    def __init__(self) -> None:
        super().__init__()
        self.pending = 0

    def filter(self, record: logging.LogRecord) -> bool:
        if self.pending and self.MESSAGE in record.getMessage():
            self.pending -= 1
            return False
        return True


_REFUSED = _RefusedHandshakes()


def _watch_refusals() -> None:
    logger = logging.getLogger("uvicorn.error")
    if _REFUSED not in logger.filters:
        logger.addFilter(_REFUSED)


class BodyTooLarge(Exception):
    """A request body (chunked, or longer than it said) passed the server's limit."""


def find_secrets(extra: Iterable[str] = ()) -> list[bytes]:
    """Values that must never reach the page: API keys in the environment and the config file."""
    found: set[str] = set()
    for name, value in os.environ.items():
        if _SECRET_NAME.search(name) and value and len(value) >= _MIN_SECRET:
            found.add(value)
    try:
        from intuitf.evaluator.providers import _read_config

        keys = _read_config().get("api_keys", {})
        if isinstance(keys, dict):
            found.update(v for v in keys.values() if isinstance(v, str) and len(v) >= _MIN_SECRET)
    except Exception:  # an unreadable config file has no keys to hide
        pass
    found.update(v for v in extra if v and len(v) >= _MIN_SECRET)
    # Longest first, so that a key containing another is blanked whole.
    return sorted((s.encode() for s in found), key=len, reverse=True)


def scrub(data: bytes, secrets_: list[bytes]) -> bytes:
    """``data`` with every secret replaced by asterisks of the same length."""
    for s in secrets_:
        if s in data:
            data = data.replace(s, b"*" * len(s))
    return data


def _split_host(host: str) -> tuple[str, str | None]:
    host = host.strip().lower()
    if host.startswith("["):
        end = host.find("]")
        if end < 0:
            return host, None
        name, rest = host[: end + 1], host[end + 1 :]
        return name, rest[1:] if rest.startswith(":") else None
    name, sep, port = host.rpartition(":")
    if not sep or not port.isdigit():
        return host, None
    return name, port


class HostPolicy:
    """Allowed Host header values: ``name`` (any port) or ``name:port``."""

    def __init__(self, allowed: Iterable[str]) -> None:
        self.any_port: set[str] = set()
        self.exact: set[tuple[str, str]] = set()
        for entry in allowed:
            name, port = _split_host(str(entry))
            if port is None:
                self.any_port.add(name)
            else:
                self.exact.add((name, port))

    def allows(self, host: str) -> bool:
        if not host:
            return False
        name, port = _split_host(host)
        if name in self.any_port:
            return True
        return port is not None and (name, port) in self.exact


class SecurityMiddleware:
    """Token, Host, Origin, body size, security headers and secret scrubbing (see module)."""

    def __init__(
        self,
        app,
        *,
        token: str,
        allowed_hosts: Iterable[str] = DEFAULT_HOSTS,
        max_body_bytes: int | None = None,
        upload_limit: int | None = None,
        secrets_: list[bytes] | None = None,
    ) -> None:
        self.app = app
        _watch_refusals()
        #: The upload limit a person set (--max-upload-mb): what a refusal names. The body may
        #: be a little larger (a form's boundaries and headers around the file).
        self.upload_limit = upload_limit if upload_limit is not None else max_body_bytes
        self.token = token
        self.hosts = HostPolicy(allowed_hosts)
        self.max_body = max_body_bytes
        self.secrets = find_secrets([token]) if secrets_ is None else secrets_
        # The token itself is what the page holds; it is not a secret to hide from it.
        self.secrets = [s for s in self.secrets if s != token.encode()]

    async def __call__(self, scope, receive, send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        host = headers.get("host", "")
        if not self.hosts.allows(host):
            await self._deny(
                scope, receive, send, 400,
                f"The Host {host!r} is not served here.",
                "Open the address intuitf serve printed (http://127.0.0.1:PORT/?token=...).",
            )  # fmt: skip
            return
        method = scope.get("method", "GET").upper() if kind == "http" else "WEBSOCKET"
        origin = headers.get("origin")
        if (
            origin is not None
            and method not in SAFE_METHODS
            and not self._same_origin(origin, host)
        ):
            await self._deny(
                scope, receive, send, 403,
                "Requests from another site are refused.",
                "Use the intuitf page itself; it never needs another site.",
            )  # fmt: skip
            return
        query = parse_qs(scope.get("query_string", b"").decode("latin-1"))
        from_query = (query.get("token") or [None])[0]
        cookie_token = _cookie(headers.get("cookie", ""), COOKIE)
        auth = headers.get("authorization", "")
        scheme, _, value = auth.partition(" ")
        from_header = value.strip() if scheme.lower() in ("token", "bearer") else None
        query_ok = self._valid(from_query)
        if not (query_ok or self._valid(from_header) or self._valid(cookie_token)):
            await self._deny(
                scope, receive, send, 401,
                "This server needs its access token.",
                "Open the address with ?token=... that `intuitf serve` printed.",
            )  # fmt: skip
            return
        if kind == "http" and self.max_body is not None:
            length = headers.get("content-length")
            if length is not None and length.isdigit() and int(length) > self.max_body:
                await self._deny(scope, receive, send, 413, too_large(self.upload_limit or 0),
                                 TOO_LARGE_HINT)  # fmt: skip
                return
        set_cookie = query_ok and cookie_token != self.token and kind == "http"
        if kind != "http" or self.max_body is None:
            await self.app(scope, receive, self._wrap_send(send, set_cookie))
            return
        # A chunked body (or one longer than its Content-Length said) is counted as it
        # arrives, and refused at the limit: nothing past it is read or spooled.
        limit = self.max_body
        seen = {"bytes": 0, "over": False, "answered": False}

        async def refuse() -> None:
            if not seen["answered"]:
                seen["answered"] = True
                await self._deny(scope, receive, send, 413, too_large(self.upload_limit or 0),
                                 TOO_LARGE_HINT)  # fmt: skip

        async def counted_receive():
            message = await receive()
            if message["type"] == "http.request":
                seen["bytes"] += len(message.get("body", b""))
                if seen["bytes"] > limit:
                    seen["over"] = True
                    raise BodyTooLarge()
            return message

        wrapped = self._wrap_send(send, set_cookie)

        async def tracked_send(message) -> None:
            # Whatever the app makes of a body cut short (a parse error), the answer is 413.
            if seen["over"]:
                await refuse()
                return
            if message["type"] == "http.response.start":
                seen["answered"] = True
            await wrapped(message)

        try:
            await self.app(scope, counted_receive, tracked_send)
        except BodyTooLarge:
            await refuse()
        if seen["over"]:
            await refuse()

    # -- helpers --------------------------------------------------------------------------
    def _valid(self, candidate: str | None) -> bool:
        return bool(candidate) and secrets.compare_digest(
            candidate.encode("utf-8", "replace"), self.token.encode()
        )

    def _same_origin(self, origin: str, host: str) -> bool:
        try:
            parts = urlsplit(origin)
        except ValueError:
            return False
        if parts.scheme not in ("http", "https") or not parts.netloc:
            return False
        netloc = parts.netloc.lower()
        if parts.port is None:  # the default port of the scheme, as a Host header would omit it
            default = "443" if parts.scheme == "https" else "80"
            if _split_host(host)[1] not in (None, default):
                return False
            return _split_host(netloc)[0] == _split_host(host)[0] and self.hosts.allows(host)
        return netloc == host.lower() and self.hosts.allows(netloc)

    def _wrap_send(self, send, set_cookie: bool):
        secrets_ = self.secrets
        state = {"text": False}

        async def wrapped(message) -> None:
            t = message["type"]
            if t == "http.response.start":
                hdrs = [
                    (k, v)
                    for k, v in message.get("headers", [])
                    if not k.lower().startswith(b"access-control-")
                ]
                have = {k.lower() for k, _ in hdrs}
                hdrs += [(k, v) for k, v in SECURITY_HEADERS if k not in have]
                ctype = next((v for k, v in hdrs if k.lower() == b"content-type"), b"")
                state["text"] = ctype.startswith((b"text/", b"application/json"))
                if set_cookie:
                    hdrs.append(
                        (
                            b"set-cookie",
                            f"{COOKIE}={self.token}; HttpOnly; SameSite=Strict; Path=/".encode(),
                        )
                    )
                message = {**message, "headers": hdrs}
            elif t == "http.response.body" and secrets_ and state["text"]:
                body = message.get("body", b"")
                if body:
                    message = {**message, "body": scrub(body, secrets_)}
            elif t == "websocket.send" and secrets_ and message.get("text"):
                text = scrub(message["text"].encode(), secrets_).decode()
                message = {**message, "text": text}
            await send(message)

        return wrapped

    async def _deny(self, scope, receive, send, status: int, detail: str, hint: str) -> None:
        body = json.dumps({"detail": detail, "hint": hint}).encode()
        headers = [
            (b"content-type", b"application/json"),
            (b"content-length", str(len(body)).encode()),
            *SECURITY_HEADERS,
        ]
        if scope["type"] == "http":
            await send({"type": "http.response.start", "status": status, "headers": headers})
            await send({"type": "http.response.body", "body": body})
            return
        # A WebSocket handshake: answer it with an HTTP response where the server can.
        message = await receive()
        if message.get("type") != "websocket.connect":
            return
        if "websocket.http.response" in (scope.get("extensions") or {}):
            await send(
                {"type": "websocket.http.response.start", "status": status, "headers": headers}
            )
            await send({"type": "websocket.http.response.body", "body": body})
            _REFUSED.pending += 1
        else:
            await send({"type": "websocket.close", "code": 1008, "reason": detail[:120]})


def _cookie(header: str, name: str) -> str | None:
    if not header:
        return None
    jar = SimpleCookie()
    try:
        jar.load(header)
    except Exception:
        return None
    morsel = jar.get(name)
    return morsel.value if morsel is not None else None


def new_token() -> str:
    """A fresh per-launch token."""
    return secrets.token_urlsafe(24)


TOKEN_FILE = ".token"


def kept_token(runs_dir) -> str:
    """The token kept in the runs folder (made on first use, readable by its owner only), so
    that a restarted server takes the pages still open on it."""
    from pathlib import Path

    path = Path(runs_dir).expanduser() / TOKEN_FILE
    try:
        token = path.read_text(encoding="utf-8").strip()
        if len(token) >= 16:
            return token
    except OSError:
        pass
    token = new_token()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(token + "\n")
    return token
