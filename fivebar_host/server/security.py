"""What keeps the daemon's API to the people it is meant for: token, limits, Host and Origin.

- **Token.** Generated on first start (32 random bytes, URL-safe) and stored in the state
  directory with mode 0600. Required as `Authorization: Bearer <token>` on every request
  when the daemon listens on an address that is not loopback (or with `--require-token`,
  e.g. on a computer shared by several users, since loopback is open to all of them) —
  except GETs of the web page's own files (`/`, `/static/…`), which hold nothing secret:
  the page asks for the token and sends it in the header of each API request.
- **Request size limits.** The body of a request is read into memory up to a limit (the
  upload limit for `POST /api/jobs` and `POST /api/dryrun`, a small one elsewhere); a
  larger body is refused with 413 before the application sees any of it.
- **Browsers.** A web page the user visits may send requests to 127.0.0.1. Requests that
  carry an `Origin` other than the daemon's own are refused (a page cannot forge that header,
  so it cannot submit, pause or cancel jobs), and on a loopback listener the `Host` header
  must name a loopback address (against DNS rebinding).
- **Query strings.** At most `MAX_QUERY_BYTES`, every `%` followed by two hex digits, UTF-8
  once decoded, no control characters; otherwise 422 `bad_query` (the framework would
  otherwise pass on replacement characters or a literal `%`).
- **Load.** At most `Policy.max_in_flight` requests are handled at once; uploads hold at
  most `Policy.max_upload_bytes_pending` bytes between them while they arrive, and at most
  `Policy.max_uploads` of them, once whole, wait for a compilation slot or compile; past
  that the answer is 503 `busy` with `Retry-After`. Below these limits a request waits its
  turn instead: uvicorn's own cap answers a plain-text 503 and counts idle connections (a
  burst of 200 connections was refused almost entirely), so connections are capped per
  client by `server.connections` instead.
- **Slow clients.** A body must keep coming: no gap longer than `Policy.body_idle_s`, and
  after the first `Policy.body_grace_s` at least `Policy.body_min_rate` bytes a second on
  average; otherwise 408 `timeout` and the connection is closed. A body that does not
  arrive whole with its request counts, while it arrives, against its client address's
  `Policy.max_slow_per_client` (503 `busy` past it). An upload takes one of the
  `max_uploads` slots only once whole, so clients dribbling their bodies (256 of them
  took every slot, one byte every 5 s) hold none, and are cut within seconds.
  (The request headers have their deadline in `server.connections`.)
- **nosniff.** Every answer carries `X-Content-Type-Options: nosniff`.

The middleware is plain ASGI (no framework types), so it runs before routing and before any
body parsing.
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import logging
import os
import re
import secrets
import stat
import urllib.parse
from collections.abc import Awaitable, Callable, MutableMapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fivebar_host.errors import FivebarError, shorten

log = logging.getLogger("fivebar.serve")

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

TOKEN_FILE = "token"
#: Body limit of every request except job uploads, bytes.
SMALL_BODY_LIMIT = 64 * 1024
#: Longest query string accepted, bytes (as sent, percent-encoded).
MAX_QUERY_BYTES = 8 * 1024
#: Requests handled at once (all routes) before new ones are refused as busy.
MAX_IN_FLIGHT = 1024
#: Uploads in progress at once (read, waiting for a compilation slot, or compiling).
MAX_UPLOADS = 256
#: Bytes those uploads may hold in memory between them (one upload alone always may).
MAX_UPLOAD_BYTES_PENDING = 256 * 1024 * 1024
#: What a busy answer's Retry-After says, s.
RETRY_AFTER_S = 2
#: A body's first seconds, in which it need not keep `BODY_MIN_RATE`, s.
BODY_GRACE_S = 10.0
#: The average rate a body must keep after `BODY_GRACE_S`, bytes/s.
BODY_MIN_RATE = 16 * 1024
#: The longest gap between two pieces of a body, s.
BODY_IDLE_S = 10.0
#: Bodies one client address may have arriving at once (beyond the first piece).
MAX_SLOW_PER_CLIENT = 32
NOSNIFF = (b"x-content-type-options", b"nosniff")
#: A '%' not followed by two hex digits.
_BAD_PERCENT = re.compile(rb"%(?![0-9A-Fa-f]{2})")
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


class SecurityError(FivebarError, RuntimeError):
    """The token file is unusable (wrong permissions, unreadable, empty)."""


def default_state_dir() -> Path:
    """`$STATE_DIRECTORY` (systemd's StateDirectory=) or `$XDG_STATE_HOME/fivebar`
    (default `~/.local/state/fivebar`): database, token and transient resume files."""
    env = os.environ.get("STATE_DIRECTORY")
    if env:
        return Path(env.split(":")[0])
    base = os.environ.get("XDG_STATE_HOME") or str(Path.home() / ".local" / "state")
    return Path(base) / "fivebar"


def is_loopback(host: str) -> bool:
    """True for a loopback address (127.0.0.0/8, ::1) or the name `localhost`."""
    h = host.strip("[]")
    if h.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:
        return False


def load_or_create_token(state_dir: Path) -> tuple[str, Path, bool]:
    """The daemon's token: read it, or create it (0600) on first start.

    Returns (token, path, created). Refuses a token file that others can read or write: a
    token anyone on the machine can read protects nothing.
    """
    path = state_dir / TOKEN_FILE
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        pass
    else:
        token = secrets.token_urlsafe(32)
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(token + "\n")
        return token, path, True
    try:
        st = path.stat()
        if st.st_mode & (stat.S_IRWXG | stat.S_IRWXO):
            raise SecurityError(f"{path}: the token file is readable or writable by others "
                                f"(mode {stat.S_IMODE(st.st_mode):04o}); run chmod 600 on it")
        token = path.read_text(encoding="ascii").strip()
    except OSError as e:
        raise SecurityError(f"{path}: cannot read the token file: {e.strerror or e}") from e
    except UnicodeDecodeError:
        raise SecurityError(f"{path}: the token file is not ASCII text") from None
    if len(token) < 16:
        raise SecurityError(f"{path}: the token file holds no usable token (delete it and "
                            "restart the daemon to make a new one)")
    return token, path, False


def query_problem(raw: bytes) -> str | None:
    """What is wrong with a raw query string, or None: too long, malformed
    percent-encoding, not UTF-8 once decoded, or control characters."""
    if len(raw) > MAX_QUERY_BYTES:
        return (f"query string of {len(raw)} bytes is over the limit of {MAX_QUERY_BYTES} "
                "bytes")
    if _BAD_PERCENT.search(raw):
        return "malformed percent-encoding in the query string: '%' must start %XX (hex)"
    try:
        text = urllib.parse.unquote_to_bytes(raw.replace(b"+", b" ")).decode("utf-8")
    except UnicodeDecodeError:
        return "the query string is not UTF-8 once percent-decoded"
    if _CONTROL.search(text):
        return "control characters in the query string"
    return None


@dataclass(frozen=True)
class Policy:
    """What the guard enforces for one listener."""

    token: str | None  # required on every request when set
    loopback: bool  # listening on a loopback address (Host header checked)
    upload_limit: int  # body limit of uploads (POST /api/jobs, /api/dryrun), bytes
    upload_paths: frozenset[str] = frozenset({"/api/jobs", "/api/dryrun"})
    #: The web page's files: no secret in them, so served without the token (GET only);
    #: the page then asks for the token and sends it with every API request.
    public_paths: frozenset[str] = frozenset({"/"})
    public_prefix: str = "/static/"
    max_in_flight: int = MAX_IN_FLIGHT
    max_uploads: int = MAX_UPLOADS
    max_upload_bytes_pending: int = MAX_UPLOAD_BYTES_PENDING
    body_grace_s: float = BODY_GRACE_S
    body_min_rate: float = BODY_MIN_RATE
    body_idle_s: float = BODY_IDLE_S
    max_slow_per_client: int = MAX_SLOW_PER_CLIENT


def _header(scope: Scope, name: bytes) -> str | None:
    for k, v in scope.get("headers", []):
        if k.lower() == name:
            return bytes(v).decode("latin-1")
    return None


def _host_of(value: str) -> str:
    """The host part of a Host header or an origin's netloc (IPv6 brackets kept off)."""
    if value.startswith("["):
        return value[1:].split("]", 1)[0]
    return value.rsplit(":", 1)[0] if value.count(":") == 1 else value


async def _reject(send: Send, status: int, error: str, message: str,
                  extra_headers: list[tuple[bytes, bytes]] | None = None) -> None:
    body = json.dumps({"error": error, "message": message}).encode()
    headers = [(b"content-type", b"application/json"),
               (b"content-length", str(len(body)).encode()),
               (b"connection", b"close")] + (extra_headers or [])
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


async def _busy(send: Send, message: str) -> None:
    await _reject(send, 503, "busy", message,
                  [(b"retry-after", str(RETRY_AFTER_S).encode())])


class Guard:
    """ASGI middleware: token, Host/Origin checks, query strings, request body limits and
    the load limits (module doc). The counters are only touched on the event loop."""

    def __init__(self, app: ASGIApp, policy: Policy) -> None:
        self.app = app
        self.policy = policy
        self.in_flight = 0  # requests past the checks, not yet answered
        self.uploads = 0  # uploads whole and waiting for a compilation slot or compiling
        self.upload_bytes = 0  # bytes the uploads in flight hold
        self.slow: dict[str, int] = {}  # per client address: bodies still arriving
        self.cut = 0  # bodies cut for coming too slowly (408)

    def is_upload(self, scope: Scope) -> bool:
        """Whether a request is a job submission."""
        return scope.get("method") == "POST" and scope.get("path") in self.policy.upload_paths

    def is_public(self, scope: Scope) -> bool:
        """Whether a request is for the web page's files (no token needed)."""
        path = str(scope.get("path", ""))
        return scope.get("method") in ("GET", "HEAD") and (
            path in self.policy.public_paths or path.startswith(self.policy.public_prefix))

    def limit_for(self, scope: Scope) -> int:
        """The body limit of a request."""
        return self.policy.upload_limit if self.is_upload(scope) else SMALL_BODY_LIMIT

    def _over_budget(self, upload: bool, more: int, held: int) -> bool:
        """Whether `more` bytes for an upload already holding `held` would overrun the
        bytes all uploads may hold (an upload alone is always within it)."""
        others = self.upload_bytes - held
        return (upload and others > 0
                and self.upload_bytes + more > self.policy.max_upload_bytes_pending)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        send = _nosniff(send)
        pol = self.policy
        host = _header(scope, b"host")
        if pol.loopback and (host is None or not is_loopback(_host_of(host))):
            await _reject(send, 421, "bad_host", f"Host {shorten(host or '')!r} is not a "
                          "loopback address; this daemon only answers requests for 127.0.0.1 "
                          "/ localhost")
            return
        origin = _header(scope, b"origin")
        if origin is not None and (host is None or origin.split("://", 1)[-1] != host):
            await _reject(send, 403, "cross_origin", f"requests from web pages of another "
                          f"origin ({shorten(origin)}) are refused")
            return
        if pol.token is not None and not self.is_public(scope):
            auth = _header(scope, b"authorization") or ""
            scheme, _, given = auth.partition(" ")
            if scheme.lower() != "bearer" or not hmac.compare_digest(
                    given.strip().encode(), pol.token.encode()):
                await _reject(send, 401, "unauthorized",
                              "this daemon needs its token: send 'Authorization: Bearer "
                              "<token>' (the token is in the daemon's state directory, file "
                              f"{TOKEN_FILE})",
                              [(b"www-authenticate", b'Bearer realm="fivebar"')])
                return
        problem = query_problem(bytes(scope.get("query_string", b"")))
        if problem is not None:
            await _reject(send, 422, "bad_query", problem)
            return
        limit = self.limit_for(scope)
        length = _header(scope, b"content-length")
        n = 0
        if length is not None:
            try:
                n = int(length)
            except ValueError:
                await _reject(send, 400, "bad_request", "malformed Content-Length header")
                return
            if n > limit:
                await _reject(send, 413, "too_large", f"request body of {n} bytes is over "
                              f"the limit of {limit} bytes")
                return
        upload = self.is_upload(scope)
        if self.in_flight >= pol.max_in_flight:
            await _busy(send, f"the daemon is handling {self.in_flight} requests, its limit; "
                        "retry shortly")
            return
        if self._over_budget(upload, max(n, 0), 0):
            await _busy(send, "the uploads in progress fill the daemon's upload memory; "
                        "nothing was queued, submit again shortly")
            return
        self.in_flight += 1
        body = _Body(self, scope, upload, limit)
        slot = False
        try:
            if not await body.read(receive, send):
                return
            if upload:
                if self.uploads >= pol.max_uploads:
                    await _busy(send, f"{self.uploads} submissions wait for compilation or "
                                "compile, the limit; nothing was queued, submit again shortly")
                    return
                self.uploads += 1
                slot = True
            await self._call(scope, receive, send, b"".join(body.chunks))
        finally:
            self.in_flight -= 1
            self.uploads -= slot
            body.release()

    async def _call(self, scope: Scope, receive: Receive, send: Send, body: bytes) -> None:
        """Hand the request to the application with its body already read."""
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)


def _nosniff(send: Send) -> Send:
    """`send` that adds `X-Content-Type-Options: nosniff` to every answer's headers."""

    async def wrapped(message: Message) -> None:
        if message["type"] == "http.response.start":
            headers = list(message.get("headers", []))
            if not any(bytes(k).lower() == NOSNIFF[0] for k, _ in headers):
                headers.append(NOSNIFF)
            message["headers"] = headers
        await send(message)

    return wrapped


class _Body:
    """One request's body as it arrives: bounded in size, in time (`Policy.body_*`), in the
    uploads' byte budget and, while it keeps arriving, in its client's slow bodies."""

    def __init__(self, guard: Guard, scope: Scope, upload: bool, limit: int) -> None:
        self.guard = guard
        self.upload = upload
        self.limit = limit
        client = scope.get("client")
        self.who = str(client[0]) if client else "?"
        self.chunks: list[bytes] = []
        self.size = 0
        self.held = 0  # bytes counted in the guard's upload budget
        self.slow = False  # counted in the client's slow bodies

    def _wait_s(self, start: float, last: float, now: float) -> float:
        """How long the next piece may take: the gap limit, and after the grace period
        the time by which the bytes so far fall below the minimum rate."""
        pol = self.guard.policy
        by_rate = start + pol.body_grace_s + self.size / pol.body_min_rate
        return max(0.0, min(last + pol.body_idle_s, by_rate) - now)

    async def read(self, receive: Receive, send: Send) -> bool:
        """Read the whole body; False when it was refused (the answer is sent)."""
        loop = asyncio.get_running_loop()
        start = last = loop.time()
        guard, pol = self.guard, self.guard.policy
        while True:
            try:
                msg = await asyncio.wait_for(receive(), self._wait_s(start, last,
                                                                     loop.time()))
            except TimeoutError:
                guard.cut += 1
                took = loop.time() - start
                await _reject(send, 408, "timeout", f"the request body came too slowly: "
                              f"{self.size} bytes in {took:.1f} s (no gap over "
                              f"{pol.body_idle_s:g} s and, after {pol.body_grace_s:g} s, at "
                              f"least {pol.body_min_rate:g} bytes/s); nothing was queued")
                return False
            if msg["type"] == "http.disconnect":
                return False
            last = loop.time()
            chunk = bytes(msg.get("body", b""))
            self.size += len(chunk)
            if self.size > self.limit:
                await _reject(send, 413, "too_large",
                              f"request body over the limit of {self.limit} bytes")
                return False
            if self.upload:
                if guard._over_budget(True, len(chunk), self.held):
                    await _busy(send, "the uploads in progress fill the daemon's upload "
                                "memory; nothing was queued, submit again shortly")
                    return False
                self.held += len(chunk)
                guard.upload_bytes += len(chunk)
            self.chunks.append(chunk)
            if not msg.get("more_body", False):
                return True
            if not self.slow:
                if guard.slow.get(self.who, 0) >= pol.max_slow_per_client:
                    await _busy(send, f"{pol.max_slow_per_client} request bodies from "
                                f"{self.who} are still arriving, the limit for one client; "
                                "nothing was queued, retry shortly")
                    return False
                guard.slow[self.who] = guard.slow.get(self.who, 0) + 1
                self.slow = True

    def release(self) -> None:
        """Give back what the body held in the guard's counts."""
        self.guard.upload_bytes -= self.held
        self.held = 0
        if self.slow:
            left = self.guard.slow.get(self.who, 1) - 1
            if left > 0:
                self.guard.slow[self.who] = left
            else:
                self.guard.slow.pop(self.who, None)
            self.slow = False
