"""What keeps the daemon's API to the people it is meant for: token, limits, Host and Origin.

- **Token.** Generated on first start (32 random bytes, URL-safe) and stored in the state
  directory with mode 0600. Required as `Authorization: Bearer <token>` on *every* request
  when the daemon listens on an address that is not loopback (or with `--require-token`,
  e.g. on a computer shared by several users, since loopback is open to all of them).
- **Request size limits.** The body of a request is read into memory up to a limit (the
  upload limit for `POST /api/jobs`, a small one elsewhere); a larger body is refused with
  413 before the application sees any of it.
- **Browsers.** A web page the user visits may send requests to 127.0.0.1. Requests that
  carry an `Origin` other than the daemon's own are refused (a page cannot forge that header,
  so it cannot submit, pause or cancel jobs), and on a loopback listener the `Host` header
  must name a loopback address (against DNS rebinding).

The middleware is plain ASGI (no framework types), so it runs before routing and before any
body parsing.
"""

from __future__ import annotations

import hmac
import ipaddress
import json
import logging
import os
import secrets
import stat
from collections.abc import Awaitable, Callable, MutableMapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fivebar_host.errors import FivebarError

log = logging.getLogger("fivebar.serve")

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

TOKEN_FILE = "token"
#: Body limit of every request except job uploads, bytes.
SMALL_BODY_LIMIT = 64 * 1024


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


@dataclass(frozen=True)
class Policy:
    """What the guard enforces for one listener."""

    token: str | None  # required on every request when set
    loopback: bool  # listening on a loopback address (Host header checked)
    upload_limit: int  # body limit of POST /api/jobs, bytes
    upload_path: str = "/api/jobs"


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


class Guard:
    """ASGI middleware: token, Host/Origin checks and request body limits (module doc)."""

    def __init__(self, app: ASGIApp, policy: Policy) -> None:
        self.app = app
        self.policy = policy

    def limit_for(self, scope: Scope) -> int:
        """The body limit of a request."""
        if scope.get("method") == "POST" and scope.get("path") == self.policy.upload_path:
            return self.policy.upload_limit
        return SMALL_BODY_LIMIT

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        pol = self.policy
        host = _header(scope, b"host")
        if pol.loopback and (host is None or not is_loopback(_host_of(host))):
            await _reject(send, 421, "bad_host", f"Host {host!r} is not a loopback address; "
                          "this daemon only answers requests for 127.0.0.1 / localhost")
            return
        origin = _header(scope, b"origin")
        if origin is not None and (host is None or origin.split("://", 1)[-1] != host):
            await _reject(send, 403, "cross_origin", f"requests from web pages of another "
                          f"origin ({origin}) are refused")
            return
        if pol.token is not None:
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
        limit = self.limit_for(scope)
        length = _header(scope, b"content-length")
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
        # Read the whole body (bounded), then replay it to the application.
        chunks: list[bytes] = []
        size = 0
        while True:
            msg = await receive()
            if msg["type"] == "http.disconnect":
                return
            chunk = bytes(msg.get("body", b""))
            size += len(chunk)
            if size > limit:
                await _reject(send, 413, "too_large",
                              f"request body over the limit of {limit} bytes")
                return
            chunks.append(chunk)
            if not msg.get("more_body", False):
                break
        body = b"".join(chunks)
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        await self.app(scope, replay, send)
